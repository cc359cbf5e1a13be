# shellcheck shell=bash
# What the stream comparisons (bench/motion_streams.sh, bench/ik_streams.sh)
# share: a release server on loopback, a wait for a quiet machine before each
# run, one `inbetween load` run with its one-line summary, and a table of
# clip vs motion runs. Sourcing it defines the functions below only.
#
#   source "$(dirname "$0")/streams_lib.sh"
#   bs_serve                   # IB_BIN, and a server: pid, http, grpc; out (reports)
#   bs_fresh_server NAME       # stops that server, starts a fresh one (stream caps at 40000): pid, http, grpc
#   bs_viewers N               # N, or the most viewers the file descriptors allow (limit − 256), saying so
#   bs_run NAME ARGS…          # waits for quiet, runs `inbetween load ARGS… --json` into $out/NAME.json
#   bs_run --now NAME ARGS…    # the same without the wait (the second run of a pair shares the first's conditions)
#   bs_compare CLIP MOTION…    # p99 receive lateness, loss and server CPU of clip vs motion runs, and the ratio
#
# QUIET (default 1.5): the 1-minute load average to wait for before each run,
# WAIT_MINUTES (default 10): the longest wait (then it runs anyway, saying so).

source "$(dirname "${BASH_SOURCE[0]}")/../scripts/lib.sh"

bs_serve() {
  cd "$IB_ROOT" || exit
  out=${OUT:-$(mktemp -d)}
  mkdir -p "$out"
  ulimit -n 65536 2>/dev/null || ulimit -n "$(ulimit -Hn)" || true
  ib_bin release
  ib_workdir
  # One caller (loopback) drives every stream, and each stream's controls are writes of its budget.
  ib_serve server --data-dir "$IB_WORK/data" --max-streams 40000 --max-streams-per-client 40000 --max-connections 40000 \
    --write-rate 100000 --write-burst 100000
  pid=$IB_PID http=$IB_HTTP grpc=$IB_GRPC
  echo "server pid $pid, $http, $grpc; reports in $out"
}

# A fresh server in place of the current one, so no earlier run's freed memory hides in "RSS before".
bs_fresh_server() {
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  ib_serve "$1" --data-dir "$IB_WORK/data-$1" --max-streams 40000 --max-streams-per-client 40000 \
    --max-connections 40000
  pid=$IB_PID http=$IB_HTTP grpc=$IB_GRPC
  echo "server pid $pid, $http"
}

# The server and the generator each hold one descriptor per viewer (and a few hundred more).
bs_viewers() {
  local fds
  fds=$(ulimit -n)
  if [ "$1" -gt $((fds - 256)) ]; then
    echo "!! $1 viewers need more than the $fds file descriptors a process may hold here: running $((fds - 256)) instead" >&2
    echo $((fds - 256))
  else
    echo "$1"
  fi
}

bs_wait_quiet() {
  local l _ quiet=${QUIET:-1.5}
  for _ in $(seq "${WAIT_MINUTES:-10}"); do
    l=$(cut -d' ' -f1 /proc/loadavg)
    if awk "BEGIN { exit !($l <= $quiet) }"; then return 0; fi
    echo "   load average $l > $quiet, waiting 60 s"
    sleep 60
  done
  echo "   still busy after ${WAIT_MINUTES:-10} minutes (load average $(cut -d' ' -f1-3 /proc/loadavg)): running anyway"
}

bs_run() { # [--now] name, then `inbetween load` arguments
  if [ "$1" = --now ]; then shift; else bs_wait_quiet; fi
  local name=$1
  shift
  echo "== $name: inbetween load $*  (before: $(cut -d' ' -f1-3 /proc/loadavg))"
  cut -d' ' -f1-3 /proc/loadavg >"$out/$name.loadavg0"
  head -1 /proc/stat >"$out/$name.stat0"
  "$IB_BIN" load "$@" --http "$http" --grpc "$grpc" --server-pid "$pid" --json >"$out/$name.json" 2>"$out/$name.err" \
    || { echo "   failed: $(tail -n 3 "$out/$name.err")"; rm -f "$out/$name.json"; return 0; }
  head -1 /proc/stat >"$out/$name.stat1"
  python3 - "$out/$name" <<'PY'
import json, sys
n = sys.argv[1]
r = json.load(open(n + ".json")); s = r["streams"]; l = s["receive_lateness"]; srv = r.get("server") or {}
a, b = ([int(x) for x in open(n + f).read().split()[1:9]] for f in (".stat0", ".stat1"))
d = [y - x for x, y in zip(a, b)]
busy = 2 * (sum(d) - d[3] - d[4]) / max(sum(d), 1)
print("   %d/%d opened, %.1f frames/s each; receive late p50 %.0f p99 %.0f max %.0f µs; loss %.2f%%; server %.2f cores "
      "(%.1f µs/frame), client %.2f; machine busy %.2f of 2 cores; load average after %s; errors %s" % (
      s["opened"], s["streams"], s["frames_per_stream_per_sec"], l["p50_us"], l["p99_us"], l["max_us"],
      100 * s["loss_ratio"], srv.get("cpu_cores", -1), srv.get("cpu_us_per_op", -1), r.get("client_cpu_cores") or -1,
      busy, r["loadavg"].split()[0], r["errors"]))
f = r.get("floor")
if f:
    print("   floor %s (%d B frames): %d/%d opened, %.1f frames/s each; receive late p99 %.0f µs; loss %.2f%%; floor %.2f cores "
          "(%.2f µs/frame); server/floor %s; errors %s" % (
          f["kind"], f["frame_bytes"], f["opened"], f["streams"], f["frames_per_stream_per_sec"],
          f["receive_lateness"]["p99_us"], 100 * f["loss_ratio"], f["cpu_cores"], f["cpu_us_per_frame"],
          "%.2f×" % f["server_to_floor"] if f["server_to_floor"] else "–", f["errors"]))
PY
}

bs_compare() { # clip run name, then motion run names: one row per motion run against the clip run
  python3 - "$out" "$@" <<'PY'
import json, os, sys
out, clip, motions = sys.argv[1], sys.argv[2], sys.argv[3:]
def load(name):
    p = os.path.join(out, name + ".json")
    if not os.path.exists(p):
        return None
    r = json.load(open(p)); s = r["streams"]
    return {"p99": s["receive_lateness"]["p99_us"], "loss": s["loss_ratio"],
            "cpu": (r.get("server") or {}).get("cpu_us_per_op", float("nan")),
            "load": open(os.path.join(out, name + ".loadavg0")).read().split()[0]}
c = load(clip)
for m in motions:
    v = load(m)
    if c is None or v is None:
        print("| %s vs %s | (a run failed) |" % (clip, m)); continue
    print("| %s vs %s | p99 %.0f → %.0f µs (×%.2f) | loss %.2f%% → %.2f%% | server %.1f → %.1f µs/frame | load average %s, %s |"
          % (clip, m, c["p99"], v["p99"], v["p99"] / max(c["p99"], 1e-9), 100 * c["loss"], 100 * v["loss"],
             c["cpu"], v["cpu"], c["load"], v["load"]))
PY
}
