#!/usr/bin/env bash
# Load shedding at 4x capacity (release build): --max-in-flight C (default 2);
# measures the capacity for a 500-pose batch sample closed loop, then offers
# 4x that rate open loop for N seconds (default 30) and prints p50/p99 of the
# admitted requests and the share shed.
#
#   scripts/overload.sh [seconds] [C]   # defaults 30 2
#   scripts/overload.sh --help          # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
INBETWEEN_SLOW=1 OVERLOAD_SECS=${1:-30} OVERLOAD_CAPACITY=${2:-2} exec cargo test --release --test system overload_p99 -- --nocapture
