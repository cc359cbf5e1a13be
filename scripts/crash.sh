#!/usr/bin/env bash
# The full kill -9 crash test: 8 uploaders (JSON, glTF, GLB, BVH, 1 KiB-4 MiB)
# against the real binary, SIGKILL at a random 50-2000 ms, N cycles (default 50).
# CRASH_SEED=<n> repeats a run.
#
#   scripts/crash.sh [cycles]   # default 50
#   scripts/crash.sh --help     # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
CRASH_CYCLES=${1:-50} exec cargo test --test system crash -- --nocapture
