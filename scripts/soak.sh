#!/usr/bin/env bash
# The soak: 200 WebSocket viewers (reconnecting every minute) against the real
# binary for N seconds (default 1800); RSS growth after the warm-up must be <= 5%.
# Usage: scripts/soak.sh [seconds]
set -euo pipefail
cd "$(dirname "$0")/.."
INBETWEEN_SLOW=1 SOAK_SECS=${1:-1800} exec cargo test --test system soak -- --nocapture
