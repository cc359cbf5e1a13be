#!/usr/bin/env bash
# The full kill -9 crash test: 8 uploaders (JSON, glTF, GLB, BVH, 1 KiB-4 MiB)
# against the real binary, SIGKILL at a random 50-2000 ms, N cycles (default 50).
# Usage: scripts/crash.sh [cycles] ; CRASH_SEED=<n> repeats a run.
set -euo pipefail
cd "$(dirname "$0")/.."
CRASH_CYCLES=${1:-50} exec cargo test --test system crash -- --nocapture
