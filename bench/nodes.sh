#!/usr/bin/env bash
# Pose throughput with 1, 2 and 3 nodes on one PostgreSQL (issue 7): starts
# release `inbetween serve` processes on a fresh schema of the local
# PostgreSQL, uploads the standard 20-joint clip through the first, then for
# each node count runs one `inbetween load` per node at the same time (the
# same total concurrency split between them) and sums their throughput.
# Every node and load generator shares this machine's cores, so the total
# cannot grow with nodes here; the figure is the per-node efficiency
# (total / nodes / one node's) and the cost of more processes.
#
#   bench/nodes.sh [seconds] [total concurrency] [mode]
#   DATABASE_URL=postgres://postgres@127.0.0.1:5432/test (default)
#   INBETWEEN_BIN=path: a binary built elsewhere instead of `cargo build --release`
#   bench/nodes.sh --help: this text
set -euo pipefail
source "$(dirname "$0")/../scripts/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
secs=${1:-10} conc=${2:-48} mode=${3:-rest-pose}
db=${DATABASE_URL:-postgres://postgres@127.0.0.1:5432/test}
ib_bin release
bin=$IB_BIN
schema=bench_nodes_$$
psql -q "$db" -c "CREATE SCHEMA $schema" >/dev/null
ib_workdir
work=$IB_WORK
cleanup() {
  ib_cleanup
  psql -q "$db" -c "DROP SCHEMA $schema CASCADE" >/dev/null 2>&1 || true
}
trap cleanup EXIT
url="$db?options=-csearch_path%3D$schema"
pids=() https=() grpcs=()
for i in 1 2 3; do
  ib_serve "node$i" --database-url "$url" --db-max-connections 4
  pids+=("$IB_PID") https+=("$IB_HTTP") grpcs+=("$IB_GRPC")
done
# The clip, uploaded through node 1 (a 1-second run uploads it and reports its id).
clip=$("$bin" load "$mode" -c 1 -d 1 --http "${https[0]}" --grpc "${grpcs[0]}" --json 2>/dev/null \
  | python3 -c 'import json,sys; print(json.load(sys.stdin)["clip_id"])')
echo "nodes on schema $schema, clip $clip, $mode, $secs s, total concurrency $conc"
printf '| nodes | throughput (req/s) | per node | efficiency vs 1 node | p50 | p99 | errors |\n|---|---|---|---|---|---|---|\n'
one=
for n in 1 2 3; do
  for i in $(seq 0 $((n - 1))); do
    "$bin" load "$mode" -c $((conc / n)) -d "$secs" --clip "$clip" --http "${https[$i]}" --grpc "${grpcs[$i]}" \
      --server-pid "${pids[$i]}" --json >"$work/load$n-$i.json" 2>"$work/load$n-$i.err" &
  done
  for j in $(jobs -p); do
    case " ${pids[*]} " in *" $j "*) ;; *) wait "$j" || true ;; esac
  done
  python3 - "$n" "$work" "${one:-0}" <<'EOF'
import json, sys
n, work, one = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
rs = [json.load(open(f"{work}/load{n}-{i}.json")) for i in range(n)]
total = sum(r["throughput"] for r in rs)
errors = sum(sum(r["errors"].values()) for r in rs)
lat = lambda q: max(r["latency"][q] for r in rs) / 1000
eff = f"{total / n / one:.2f}" if one else "1.00"
print(f"| {n} | {total:,.0f} | {total / n:,.0f} | {eff} | {lat('p50_us'):.2f} ms | {lat('p99_us'):.2f} ms | {errors} |")
open(f"{work}/total{n}", "w").write(str(total))
EOF
  [ -n "$one" ] || one=$(cat "$work/total1")
done
