#!/usr/bin/env bash
# Build-budget figures (issue 15, release build, default settings): the
# issue's two concurrent ~50 KB looping constant-speed uploads (time to 422,
# /healthz and gRPC Ping p99, peak RSS), then the most expensive clip the
# default max_build_work admits (upload time, peak RSS). Prints FIGURE lines.
#
#   scripts/build_budget.sh          # run it
#   scripts/build_budget.sh --help   # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
INBETWEEN_SLOW=1 exec cargo test --release --test system build_budget_figures -- --nocapture
