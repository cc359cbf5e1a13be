#!/usr/bin/env bash
# Our retargeting against three.js's, a peer nobody here wrote (docs/characters.md,
# "Agreement with three.js"). Starts a server, imports the CMU take
# examples/bvh/131_01.bvh and the character examples/gltf/CesiumMan, asks for the
# take played on CesiumMan at every one of its 994 frames, and runs three.js's
# SkeletonUtils.retarget and retargetClip (three pinned in
# scripts/peers/retarget-threejs/package-lock.json, installed with `npm ci`) on the
# same two files read by three.js's own BVHLoader and GLTFLoader, its options set to
# our documented rule. Fails when a joint's model-space rotation or the hips'
# position differs by more than the limits below.
#
#   scripts/peer_retarget.sh          # builds the debug binary
#   scripts/peer_retarget.sh --help   # this text
#
# INBETWEEN_BIN: a binary built elsewhere. Needs node and npm; npm reaches only
# the npm registry, into scripts/peers/retarget-threejs/node_modules.
#
# The limits are the measured maxima with a margin: the two agree to f32 rounding.
#   MAX_DEG       retarget at the take's keys: 5.3e-5 degrees measured
#   MAX_DEG_CLIP  retargetClip, whose frame times are f64 sums the server reads as
#                 f32 seconds: 1.2e-3 degrees measured (the right hand in frame 808)
#   MAX_HIPS      the hips' model position: 8.3e-7 measured (CesiumMan's metres)
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"

MAX_DEG=7e-5
MAX_DEG_CLIP=1.5e-3
MAX_HIPS=1e-6

peer=scripts/peers/retarget-threejs
(cd "$peer" && npm ci --no-audit --no-fund --loglevel=error)

ib_bin debug
ib_workdir # before ib_serve: its --data-dir argument is expanded first
ib_serve peer-retarget --data-dir "$IB_WORK/data"

node "$peer/compare.mjs" --http "$IB_HTTP" \
  --bvh examples/bvh/131_01.bvh --gltf examples/gltf/CesiumMan/CesiumMan.gltf \
  --max-deg "$MAX_DEG" --max-deg-clip "$MAX_DEG_CLIP" --max-hips "$MAX_HIPS"
