#!/usr/bin/env bash
# Motion streams vs clip streams (issue 16; BENCHMARKS.md "Motion streams"):
# 500 streams at 60 fps of the 64-joint chain clip, then of the three-layer
# motion (`inbetween load … --motion three-layers`), on one release server on
# loopback, alternating, for each transport (gRPC, WebSocket protobuf,
# WebSocket JSON) and ROUNDS rounds. Before each run it waits (60 s at a time,
# up to WAIT_MINUTES, default 10) until the 1-minute load average is at most
# QUIET (default 1.5), and it prints each report's summary, and at the end
# each pair's p99 ratio; the JSON reports stay in $OUT.
#
#   bench/motion_streams.sh              # 3 rounds of 20-second windows, about 25 minutes
#   ROUNDS="1" SECS=5 bench/motion_streams.sh   # one short round
#   CASES="grpc" bench/motion_streams.sh # transports among: grpc wspb ws
#   STREAMS=50 SECS=5 ROUNDS=1 bench/motion_streams.sh  # a small smoke run
#   INBETWEEN_BIN=path bench/motion_streams.sh  # a binary built elsewhere
#   bench/motion_streams.sh --help       # this text
set -euo pipefail
source "$(dirname "$0")/streams_lib.sh"
ib_help "$@"
bs_serve

common=(-c "${STREAMS:-500}" --fps 60 -d "${SECS:-20}" --joints 64)
runs=()
for round in ${ROUNDS:-1 2 3}; do
  for case in ${CASES:-grpc wspb ws}; do
    case $case in
      grpc) transport=(grpc-stream) ;;
      wspb) transport=(ws-stream --protobuf) ;;
      ws) transport=(ws-stream) ;;
      *) echo "unknown case $case (grpc, wspb, ws)" >&2; exit 2 ;;
    esac
    bs_run "$case-clip-$round" "${transport[@]}" "${common[@]}"
    bs_run "$case-motion-$round" "${transport[@]}" "${common[@]}" --motion three-layers
    runs+=("$case-clip-$round $case-motion-$round")
  done
done
echo "== clip vs motion (p99 receive lateness, loss, server CPU per frame, load average before each run)"
for pair in "${runs[@]}"; do
  # shellcheck disable=SC2086 # the pair is two run names
  bs_compare $pair
done
echo "reports: $out"
