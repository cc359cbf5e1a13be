#!/usr/bin/env bash
# Load shedding at 4x capacity: --max-in-flight C (default 8), 4C closed-loop
# clients asking for poses for N seconds (default 30); prints p50/p99 of the
# admitted requests and the number shed. Usage: scripts/overload.sh [seconds] [capacity]
set -euo pipefail
cd "$(dirname "$0")/.."
OVERLOAD_SECS=${1:-30} OVERLOAD_CAPACITY=${2:-8} exec cargo test --test ops overload_p99 -- --ignored --nocapture
