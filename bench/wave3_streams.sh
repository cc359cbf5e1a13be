#!/usr/bin/env bash
# Characters, graphs and springs on streams (BENCHMARKS.md "Characters, graphs
# and springs on streams"): STREAMS (default 500) WebSocket streams (protobuf)
# at 60 fps of a clip, then of the same clip played through a wave-3 feature,
# on one release server on loopback, alternating, for ROUNDS rounds:
#   springs   the Fox's walk vs examples/motions/fox-tail-springs.json (the walk
#             with its tail as a spring chain, 120 Hz substeps)
#   graph     the Fox's walk vs examples/graphs/fox-locomotion.json, each stream
#             setting `speed` once a second (0.5, then 2.5: idle, walk/run, …)
#   retarget  the CMU take 131_01 vs the take played on CesiumMan (a character)
# Each run waits for a quiet machine first (bench/streams_lib.sh: QUIET,
# WAIT_MINUTES); the JSON reports stay in $OUT.
#
#   bench/wave3_streams.sh                          # 3 rounds of 20-second windows
#   ROUNDS="1" SECS=5 bench/wave3_streams.sh         # one short round
#   CASES="graph" bench/wave3_streams.sh             # among: springs graph retarget
#   STREAMS=50 SECS=5 ROUNDS=1 bench/wave3_streams.sh  # a small smoke run
#   bench/wave3_streams.sh --help                   # this text
set -euo pipefail
source "$(dirname "$0")/streams_lib.sh"
ib_help "$@"
bs_serve

post() { # path, file: the answer's body
  curl -sf -X POST --data-binary "@$2" -H 'Content-Type: application/octet-stream' "$http$1"
}
id_of() { # name: the id of the clip of that name
  curl -sf "$http/v1/clips?name=$1" | python3 -c 'import json,sys; print(json.load(sys.stdin)["clips"][0]["id"])'
}
post "/v1/clips/import?replace=true&scale=0.01" examples/gltf/Fox/Fox.glb >/dev/null
post "/v1/clips/import?replace=true&name=131_01" examples/bvh/131_01.bvh >/dev/null
post "/v1/characters/import?replace=true&name=cesium" examples/gltf/CesiumMan/CesiumMan.gltf >/dev/null
sed -e "s/name:Survey/$(id_of Survey)/" -e "s/name:Walk/$(id_of Walk)/" -e "s/name:Run/$(id_of Run)/" \
  examples/graphs/fox-locomotion.json >"$IB_WORK/graph.json"
curl -sf -X POST --data-binary "@$IB_WORK/graph.json" -H 'Content-Type: application/json' \
  "$http/v1/graphs?replace=true" >/dev/null
echo '{"layers": [{"graph": "name:fox-locomotion"}]}' >"$IB_WORK/graph-motion.json"
echo '{"layers": [{"clip": "name:131_01"}], "character": "name:cesium"}' >"$IB_WORK/retarget.json"

common=(ws-stream --protobuf -c "${STREAMS:-500}" --fps 60 -d "${SECS:-20}")
runs=()
for round in ${ROUNDS:-1 2 3}; do
  for case in ${CASES:-springs graph retarget}; do
    case $case in
      springs) clip=$(id_of Walk) feature=(--motion-file examples/motions/fox-tail-springs.json) ;;
      graph) clip=$(id_of Walk) feature=(--motion-file "$IB_WORK/graph-motion.json" --set speed=0.5,2.5) ;;
      retarget) clip=$(id_of 131_01) feature=(--motion-file "$IB_WORK/retarget.json") ;;
      *) echo "unknown case $case (springs, graph, retarget)" >&2; exit 2 ;;
    esac
    bs_run "$case-clip-$round" "${common[@]}" --clip "$clip"
    bs_run "$case-feature-$round" "${common[@]}" "${feature[@]}"
    runs+=("$case-clip-$round $case-feature-$round")
  done
done
echo "== clip vs feature (p99 receive lateness, loss, server CPU per frame, load average before each run)"
for pair in "${runs[@]}"; do
  # shellcheck disable=SC2086 # the pair is two run names
  bs_compare $pair
done
echo "reports: $out"
