#!/usr/bin/env bash
# Runs the core sampling benchmarks and prints the BENCHMARKS.md table:
# criterion's median per 64-joint pose, and per joint (÷ 64).
#   scripts/bench_core.sh            # all benchmarks (about 2 minutes)
#   scripts/bench_core.sh rbt_64     # a criterion filter
#   scripts/bench_core.sh --help     # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
cargo bench --bench sampling -- "${1:-}" >/dev/null 2>&1
python3 - <<'PY'
import json, pathlib
root = pathlib.Path("target/criterion")
rows = []
for est in sorted(root.glob("*/*/new/estimates.json")):
    group, bench = est.parts[-4], est.parts[-3]
    median_ns = json.loads(est.read_text())["median"]["point_estimate"]
    import re
    m = re.search(r"_(\d+)_joints$", bench)
    per = 64 if group.endswith("64_joints") or group.startswith("mode_64") else int(m.group(1)) if m else 1
    rows.append((group, bench, median_ns, median_ns / per))
print("| group | benchmark | median per call | per joint |")
print("|---|---|---|---|")
for g, b, m, p in rows:
    call = f"{m/1000:.2f} µs" if m >= 1000 else f"{m:.1f} ns"
    print(f"| {g} | {b} | {call} | {p:.1f} ns |")
PY
