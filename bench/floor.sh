#!/usr/bin/env bash
# The streaming floor (issue 19; BENCHMARKS.md "Streaming floor"): STREAMS
# (default 1,000) independent streams of the 20-joint clip at 60 fps against
# one release server on loopback, then, in the same `inbetween load --floor`
# invocation, the same streams against a bare sender (`inbetween load-floor`, its
# own process) writing one of the server's own frames to as many connections at
# the same rate; for gRPC, WebSocket protobuf and WebSocket JSON, ROUNDS rounds.
# Before each run it waits for a quiet machine (QUIET, WAIT_MINUTES: see
# bench/streams_lib.sh). At the end, one row per run: server and floor CPU per
# delivered frame, their ratio, loss and p99 receive lateness of each. The JSON
# reports stay in $OUT.
#
#   bench/floor.sh                               # 2 rounds of 10-second windows, about 5 minutes
#   STREAMS=100 SECS=3 ROUNDS=1 bench/floor.sh   # a smoke run
#   CASES="grpc" bench/floor.sh                  # transports among: grpc wspb ws
#   INBETWEEN_BIN=path bench/floor.sh            # a binary built elsewhere
#   bench/floor.sh --help                        # this text
set -euo pipefail
source "$(dirname "$0")/streams_lib.sh"
ib_help "$@"
bs_serve

common=(-c "${STREAMS:-1000}" --fps 60 -d "${SECS:-10}" --joints 20 --floor)
runs=()
for round in ${ROUNDS:-1 2}; do
  for case in ${CASES:-grpc wspb ws}; do
    case $case in
      grpc) transport=(grpc-stream) ;;
      wspb) transport=(ws-stream --protobuf) ;;
      ws) transport=(ws-stream) ;;
      *) echo "unknown case $case (grpc, wspb, ws)" >&2; exit 2 ;;
    esac
    bs_run "$case-floor-$round" "${transport[@]}" "${common[@]}"
    runs+=("$case-floor-$round")
  done
done
echo "== server vs floor (CPU per delivered frame; loss; p99 receive lateness; load average before each run)"
python3 - "$out" "${runs[@]}" <<'PY'
import json, os, sys
out, runs = sys.argv[1], sys.argv[2:]
print("| run | frame | server CPU/frame | floor CPU/frame | ratio | server cores / floor cores | loss server / floor | p99 server / floor | load average |")
print("|---|---|---|---|---|---|---|---|---|")
for name in runs:
    p = os.path.join(out, name + ".json")
    if not os.path.exists(p):
        print("| %s | (failed) |" % name); continue
    r = json.load(open(p)); s = r["streams"]; f = r.get("floor") or {}; srv = r.get("server") or {}
    ratio = f.get("server_to_floor")
    print("| %s | %s, %d B | %.2f µs | %.2f µs | %s | %.2f / %.2f | %.2f%% / %.2f%% | %.2f / %.2f ms | %s |" % (
        name, f.get("kind", "?"), f.get("frame_bytes", 0), srv.get("cpu_us_per_op", float("nan")),
        f.get("cpu_us_per_frame", float("nan")), "%.2f×" % ratio if ratio else "–",
        srv.get("cpu_cores", float("nan")), f.get("cpu_cores", float("nan")),
        100 * s["loss_ratio"], 100 * f.get("loss_ratio", float("nan")),
        s["receive_lateness"]["p99_us"] / 1000, f.get("receive_lateness", {}).get("p99_us", float("nan")) / 1000,
        open(os.path.join(out, name + ".loadavg0")).read().split()[0]))
PY
echo "reports: $out"
