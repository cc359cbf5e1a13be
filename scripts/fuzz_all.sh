#!/usr/bin/env bash
# Runs every fuzz target for SECONDS_EACH (default 600) seconds, one after
# the other in one process (the machine is shared), and prints libFuzzer's
# final stats per target. Seeds first (fuzz/seed.sh). A crash stops the
# script with the artifact in fuzz/artifacts/<target>/.
#   scripts/fuzz_all.sh [seconds_each] [targets...]
#   scripts/fuzz_all.sh --help  # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT/fuzz"
EACH=${1:-600}
shift || true
TARGETS=${*:-import_gltf import_bvh clip_json import_evaluate motion_json graph_json}
export RUSTC_BOOTSTRAP=1
bash seed.sh >/dev/null
for t in $TARGETS; do
  echo "== $t, $EACH s"
  cargo fuzz run "$t" -- -max_total_time="$EACH" -max_len=262144 -rss_limit_mb=2048 \
    -timeout=10 -print_final_stats=1 2>&1 | tee "/tmp/fuzz-$t.log" | grep -E "^(stat::|Done|==[0-9]+==|SUMMARY)" || true
  grep -q "^Done" "/tmp/fuzz-$t.log" || { echo "$t did not finish cleanly; see /tmp/fuzz-$t.log"; exit 1; }
done
