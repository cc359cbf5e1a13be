#!/usr/bin/env bash
# The performance record in one command: builds a release server, starts it
# on loopback, runs the standard load scenarios with `inbetween load` and the
# core comparison with criterion, and rewrites the generated tables of
# BENCHMARKS.md (between the `bench/run.sh` marker comments).
#
#   bench/run.sh              # standard scenarios, about 10 minutes
#   bench/run.sh --quick      # 2-second windows, a tenth of the streams (a smoke run of the script)
#   bench/run.sh --long       # adds the 10-minute drift run and the 10-minute soak
#   bench/run.sh --no-core    # skips the criterion comparison
#   bench/run.sh --no-broadcasts  # skips bench/broadcasts.sh (20,000 viewers at 10 fps, 5,000 at 30 fps)
#   bench/run.sh --no-write   # prints the tables instead of editing BENCHMARKS.md
#   BENCH_SECS=4 bench/run.sh # shorter windows (default 10 s)
#   INBETWEEN_BIN=path bench/run.sh  # a binary built elsewhere instead of `cargo build --release`
#   bench/run.sh --help       # this text
#
# Everything talks to 127.0.0.1 only. Results (JSON reports) stay in
# $BENCH_OUT (default: a temporary directory, printed at the end).
set -euo pipefail
source "$(dirname "$0")/../scripts/lib.sh"
cd "$IB_ROOT"
secs=${BENCH_SECS:-10} scale=1 long=0 core=1 broadcasts=1 write=1
for arg in "$@"; do
  case $arg in
    -h | --help) ib_usage; exit 0 ;;
    --quick) secs=2 scale=10 ;;
    --long) long=1 ;;
    --no-core) core=0 ;;
    --no-broadcasts) broadcasts=0 ;;
    --no-write) write=0 ;;
    *) echo "unknown option $arg (see --help)" >&2; exit 2 ;;
  esac
done
target=${CARGO_TARGET_DIR:-$IB_ROOT/target}
out=${BENCH_OUT:-$(mktemp -d)}
mkdir -p "$out"
ulimit -n 65536 2>/dev/null || ulimit -n "$(ulimit -Hn)" || true

# INBETWEEN_BIN: a binary built elsewhere (figures from a debug build mean little).
[ -n "${INBETWEEN_BIN:-}" ] || echo "== building the release binary"
ib_bin release
bin=$IB_BIN
n() { echo $(($1 / scale)); }

# Stream caps raised for the load (every stream comes from 127.0.0.1).
ib_workdir
ib_serve server --data-dir "$IB_WORK/data" --max-streams 40000 --max-streams-per-client 40000
pid=$IB_PID http=$IB_HTTP grpc=$IB_GRPC
echo "server pid $pid, $http, $grpc; reports in $out"

load() { # name, then `inbetween load` arguments
  local name=$1; shift
  echo "== $name: inbetween load $*"
  "$bin" load "$@" --http "$http" --grpc "$grpc" --server-pid "$pid" --json >"$out/$name.json" 2>"$out/$name.err" \
    || { echo "   failed: $(tail -n 3 "$out/$name.err")"; rm -f "$out/$name.json"; return 0; }
  python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print("   ok %d, %.0f/s, errors %s" % (r["ok"], r["throughput"], r["errors"]))' "$out/$name.json"
}

# Unary: each pair on the same server, alternating, two rounds.
for round in 1 2; do
  load "grpc-ping-$round" grpc-ping -c 32 -d "$secs"
  load "grpc-sample-$round" grpc-sample -c 32 -d "$secs" --joints 20
  load "rest-health-$round" rest-health -c 32 -d "$secs"
  load "rest-pose-$round" rest-pose -c 32 -d "$secs" --joints 20
done
# Open loop: latency without coordinated omission at a fixed rate.
load grpc-sample-open grpc-sample -c 64 -d "$secs" --rate 5000 --joints 20
load rest-pose-open rest-pose -c 64 -d "$secs" --rate 5000 --joints 20

# Streams of the 20-joint clip at 60 fps; the 1,000-stream runs then measure the streaming floor (issue 19).
load grpc-stream-1000 grpc-stream -c "$(n 1000)" -d "$secs" --fps 60 --floor
load ws-stream-1000 ws-stream -c "$(n 1000)" -d "$secs" --fps 60 --floor
load ws-stream-1000-protobuf ws-stream -c "$(n 1000)" -d "$secs" --fps 60 --protobuf --floor
load grpc-stream-shared-20000 grpc-stream -c "$(n 20000)" -d "$secs" --fps 60 --shared
# The same 20,000 shared viewers at 10 fps: what one playback's fan-out sustains when 60 fps is more than the cores can send.
load grpc-stream-shared-20000-10fps grpc-stream -c "$(n 20000)" -d "$secs" --fps 10 --shared
# The knees: step up from 250 streams until p99 receive lateness > 2 ms or > 0.1% frames lost.
load grpc-stream-ramp grpc-stream -c "$(n 250)" -d "$secs" --fps 60 --ramp --ramp-factor 2 --ramp-max "$(n 8000)"
load ws-stream-ramp ws-stream -c "$(n 250)" -d "$secs" --fps 60 --ramp --ramp-factor 2 --ramp-max "$(n 8000)" --protobuf

if [ "$long" = 1 ]; then
  load grpc-stream-drift-10min grpc-stream -c 1000 -d 600 --fps 60
  # The soak: half of the grpc-sample capacity measured above, open loop, 10 minutes.
  rate=$(python3 -c 'import json,sys; print(int(json.load(open(sys.argv[1]))["throughput"] / 2))' "$out/grpc-sample-1.json")
  load soak-grpc-sample-10min grpc-sample -c 64 -d 600 --rate "$rate" --joints 20
fi

if [ "$broadcasts" = 1 ]; then
  # Issue 19's broadcast scenarios, each on a fresh server of the same binary (bench/broadcasts.sh); the idle
  # record server above stays up. A short wait for a quiet machine, since the generator shares the two cores.
  echo "== broadcasts: bench/broadcasts.sh"
  OUT="$out/broadcasts" INBETWEEN_BIN=$bin SECS=$((secs * 2)) WAIT_MINUTES=${WAIT_MINUTES:-3} \
    SCENARIOS="$(n 20000)x10 $(n 5000)x30" bash bench/broadcasts.sh >"$out/broadcasts.txt" 2>&1 \
    || echo "   failed: $(tail -n 3 "$out/broadcasts.txt")"
fi

if [ "$core" = 1 ]; then
  echo "== criterion: our sampling vs the ozz-style kernel, and the Catmull-Rom RBT cases"
  cargo bench --bench sampling -- 'versus_ozz|rbt_64_joints/catmull_rom' >"$out/criterion.txt" 2>&1 || true
fi

echo "== writing the tables"
python3 bench/tables.py "$out" "$target/criterion" "$(git rev-parse --short HEAD)" $([ "$write" = 1 ] && echo BENCHMARKS.md)
echo "reports: $out"
