#!/usr/bin/env bash
# Motion streams vs clip streams (issue 16; BENCHMARKS.md "Motion streams"):
# 500 streams at 60 fps of the 64-joint chain clip, then of the three-layer
# motion (`inbetween load … --motion three-layers`), on one release server on
# loopback, alternating, for each transport (gRPC, WebSocket protobuf,
# WebSocket JSON) and ROUNDS rounds. Before each run it waits (60 s at a time,
# up to 10 minutes) until the 1-minute load average is at most 1.5, and it
# prints each report's summary; the JSON reports stay in $OUT.
#
#   bench/motion_streams.sh              # 3 rounds of 20-second windows, about 25 minutes
#   ROUNDS="1" SECS=5 bench/motion_streams.sh   # one short round
#   CASES="grpc" bench/motion_streams.sh # transports among: grpc wspb ws
#   INBETWEEN_BIN=path bench/motion_streams.sh  # a binary built elsewhere
#   bench/motion_streams.sh --help       # this text
set -euo pipefail
source "$(dirname "$0")/../scripts/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
out=${OUT:-$(mktemp -d)}
mkdir -p "$out"
ulimit -n 65536 2>/dev/null || ulimit -n "$(ulimit -Hn)" || true
ib_bin release
ib_workdir
ib_serve server --data-dir "$IB_WORK/data" --max-streams 40000 --max-streams-per-client 40000
pid=$IB_PID http=$IB_HTTP grpc=$IB_GRPC
echo "server pid $pid, $http, $grpc; reports in $out"

wait_quiet() {
  local l _
  for _ in $(seq 10); do
    l=$(cut -d' ' -f1 /proc/loadavg)
    if awk "BEGIN { exit !($l <= 1.5) }"; then return 0; fi
    echo "   load average $l > 1.5, waiting 60 s"
    sleep 60
  done
  echo "   still busy after 10 minutes"
}

run() { # name, then `inbetween load` arguments
  local name=$1
  shift
  wait_quiet
  echo "== $name: inbetween load $*  (before: $(cut -d' ' -f1-3 /proc/loadavg))"
  head -1 /proc/stat >"$out/$name.stat0"
  "$IB_BIN" load "$@" --http "$http" --grpc "$grpc" --server-pid "$pid" --json >"$out/$name.json" 2>"$out/$name.err" \
    || { echo "   failed: $(tail -n 3 "$out/$name.err")"; return 0; }
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
PY
}

common=(-c 500 --fps 60 -d "${SECS:-20}" --joints 64)
for round in ${ROUNDS:-1 2 3}; do
  for case in ${CASES:-grpc wspb ws}; do
    case $case in
      grpc) transport=(grpc-stream) ;;
      wspb) transport=(ws-stream --protobuf) ;;
      ws) transport=(ws-stream) ;;
      *) echo "unknown case $case (grpc, wspb, ws)" >&2; exit 2 ;;
    esac
    run "$case-clip-$round" "${transport[@]}" "${common[@]}"
    run "$case-motion-$round" "${transport[@]}" "${common[@]}" --motion three-layers
  done
done
echo "reports: $out"
