# shellcheck shell=bash
# The scripts' shared library: `--help` from a script's own header comment,
# the `inbetween` binary, and servers started on loopback ports the kernel
# picks, stopped (with their work directory removed) when the script exits.
# Sourcing it only defines IB_ROOT and the functions below.
#
#   source "$(dirname "$0")/lib.sh"       # from scripts/ (bench/: ../scripts/lib.sh)
#   ib_help "$@"                          # -h/--help: print the header comment, exit 0
#   ib_bin release                        # IB_BIN: $INBETWEEN_BIN, or cargo build (release|debug)
#   ib_serve NAME --data-dir "$IB_WORK/data"   # IB_PID, IB_HTTP, IB_GRPC of a running server

IB_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
IB_PIDS=()
IB_WORK=

# Prints the calling script's header: the comment lines after the shebang.
ib_usage() {
  awk 'NR == 1 { next } /^#/ { sub(/^# ?/, ""); print; next } { exit }' "$0"
}

# Exits 0 after printing the usage if any argument is -h or --help.
ib_help() {
  local arg
  for arg in "$@"; do
    case $arg in -h | --help) ib_usage; exit 0 ;; esac
  done
}

# Sets IB_WORK to a fresh temporary directory and stops everything at exit.
# A script with more to undo defines its own EXIT trap that calls ib_cleanup.
ib_workdir() {
  IB_WORK=$(mktemp -d)
  trap ib_cleanup EXIT
}

# Stops the servers this script started and removes IB_WORK.
ib_cleanup() {
  local p
  for p in "${IB_PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${IB_PIDS[@]}"; do wait "$p" 2>/dev/null || true; done
  if [ -n "$IB_WORK" ]; then rm -rf "$IB_WORK"; fi
}

# PROFILE (release|debug): sets IB_BIN to $INBETWEEN_BIN if given (a binary
# built elsewhere), else builds the binary with cargo and points at it.
ib_bin() {
  local profile=${1:-release}
  if [ -n "${INBETWEEN_BIN:-}" ]; then
    IB_BIN=$INBETWEEN_BIN
    return
  fi
  local flags=(--quiet --bin inbetween)
  [ "$profile" = release ] && flags+=(--release)
  (cd "$IB_ROOT" && cargo build "${flags[@]}")
  local target=${CARGO_TARGET_DIR:-target}
  case $target in /*) ;; *) target=$IB_ROOT/$target ;; esac
  IB_BIN=$target/$profile/inbetween
}

# NAME [serve args…]: starts `$IB_BIN serve` with both listeners on
# 127.0.0.1:0 (logs in $IB_WORK/NAME.out and NAME.err; INBETWEEN_LOG defaults
# to warn), waits for its address lines and sets IB_PID, IB_HTTP, IB_GRPC.
# Exits with the server's log if it does not start within 30 s.
ib_serve() {
  local name=$1 _
  shift
  [ -n "$IB_WORK" ] || ib_workdir
  INBETWEEN_LOG=${INBETWEEN_LOG:-warn} "$IB_BIN" serve --listen 127.0.0.1:0 --grpc-listen 127.0.0.1:0 "$@" \
    >"$IB_WORK/$name.out" 2>"$IB_WORK/$name.err" &
  IB_PID=$!
  IB_PIDS+=("$IB_PID")
  for _ in $(seq 300); do
    grep -q "gRPC listening" "$IB_WORK/$name.out" 2>/dev/null && break
    kill -0 "$IB_PID" 2>/dev/null || break
    sleep 0.1
  done
  # Both lines are written at once, after both listeners are bound.
  IB_HTTP=$(sed -n 's/^inbetween listening on //p' "$IB_WORK/$name.out")
  IB_GRPC=$(sed -n 's/^inbetween gRPC listening on //p' "$IB_WORK/$name.out")
  if [ -z "$IB_HTTP" ] || [ -z "$IB_GRPC" ]; then
    echo "the server ($name) did not start:" >&2
    cat "$IB_WORK/$name.err" >&2
    exit 1
  fi
}
