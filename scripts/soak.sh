#!/usr/bin/env bash
# The soak: 200 WebSocket viewers (reconnecting every minute) against the real
# binary for N seconds (default 1800); RSS growth after the warm-up must be <= 5%.
#
#   scripts/soak.sh [seconds]   # default 1800
#   scripts/soak.sh --help      # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
INBETWEEN_SLOW=1 SOAK_SECS=${1:-1800} exec cargo test --test system soak -- --nocapture
