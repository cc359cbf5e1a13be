#!/usr/bin/env bash
# IK streams vs clip streams (issue 17; BENCHMARKS.md "IK streams"): in one
# invocation, 500 WebSocket streams at 60 fps of the 64-joint chain clip, then
# 500 of the foot-ik motion (`inbetween load ws-stream … --motion foot-ik`: a
# 64-joint walk whose two feet two `two_bone` constraints plant every frame),
# on one release server on loopback, for each transport (WebSocket protobuf
# and JSON by default) and round. Before each pair it waits (60 s at a time,
# up to WAIT_MINUTES) until the 1-minute load average is at most QUIET, then
# runs the clip and the motion back to back (so both see the same machine),
# printing each run's summary; at the end, per transport and round, the p99
# receive lateness, the frame loss and the server's CPU per frame of both,
# and the p99 ratio. The JSON reports stay in $OUT. CASES="grpc" adds gRPC
# streams (`StreamRequest.motion` with its `ik`).
#
#   bench/ik_streams.sh                  # 1 round, 20-second windows, about 3 minutes on a quiet machine
#   ROUNDS="1 2 3" bench/ik_streams.sh   # three rounds
#   CASES="wspb" bench/ik_streams.sh     # transports among: wspb ws grpc (default: wspb ws)
#   SECS=5 STREAMS=50 bench/ik_streams.sh  # a short, small run (a smoke run of the script)
#   QUIET=1.5 WAIT_MINUTES=10            # the load average to wait for, and how long (defaults)
#   INBETWEEN_BIN=path bench/ik_streams.sh  # a binary built elsewhere
#   bench/ik_streams.sh --help           # this text
set -euo pipefail
source "$(dirname "$0")/streams_lib.sh"
ib_help "$@"
bs_serve

common=(-c "${STREAMS:-500}" --fps 60 -d "${SECS:-20}" --joints 64)
runs=()
for round in ${ROUNDS:-1}; do
  for case in ${CASES:-wspb ws}; do
    case $case in
      wspb) transport=(ws-stream --protobuf) ;;
      ws) transport=(ws-stream) ;;
      grpc) transport=(grpc-stream) ;;
      *) echo "unknown case $case (wspb, ws, grpc)" >&2; exit 2 ;;
    esac
    bs_run "$case-clip-$round" "${transport[@]}" "${common[@]}"
    bs_run --now "$case-foot-ik-$round" "${transport[@]}" "${common[@]}" --motion foot-ik
    runs+=("$case-clip-$round $case-foot-ik-$round")
  done
done
echo "== clip vs foot-ik (p99 receive lateness, loss, server CPU per frame, load average before each run)"
for pair in "${runs[@]}"; do
  # shellcheck disable=SC2086 # the pair is two run names
  bs_compare $pair
done
echo "reports: $out"
