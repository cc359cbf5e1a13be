#!/usr/bin/env bash
# The cost model's figures (issue 15), on the release build with the default limits:
# the issue's attack (10,000 poses of a 4,096-joint clip) refused and how fast; the
# largest /sample answer the default max_answer_bytes admits for a 1,000-joint clip,
# its size, its time to a fast reader (curl) and the server's peak RSS meanwhile; one
# pose more refused with answer_too_large.
#
#   scripts/answer_cost.sh            # builds the release binary (or INBETWEEN_BIN=…)
#   scripts/answer_cost.sh --help
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
ib_bin release
ib_workdir
ib_serve cost --data-dir "$IB_WORK/data"

clip() { # NAME JOINTS: a clip of JOINTS root joints, each with a linear translation track
  python3 -c "import json,sys; n=int(sys.argv[2]); print(json.dumps({'name': sys.argv[1], 'tracks': [
    {'joint': f'j{j}', 'channel': 'translation', 'times': [0, 1], 'values': [[0, 0, 0], [1, 2, 3]]}
    for j in range(n)]}))" "$1" "$2"
}
create() { # FILE: the new clip's id
  curl -sf -H 'content-type: application/json' --data-binary @"$1" "$IB_HTTP/v1/clips" |
    python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])'
}
sample() { # ID BODY: "status bytes seconds" of POST /sample, the body to $IB_WORK/answer
  curl -s -o "$IB_WORK/answer" -w '%{http_code} %{size_download} %{time_total}\n' \
    -H 'content-type: application/json' -d "$2" "$IB_HTTP/v1/clips/$1/sample"
}
rss() { awk -v k="$1:" '$1 == k { print int($2 / 1024) " MiB" }' "/proc/$IB_PID/status"; }

clip big 4096 >"$IB_WORK/big.json"
clip wide 1000 >"$IB_WORK/wide.json"
big=$(create "$IB_WORK/big.json")
wide=$(create "$IB_WORK/wide.json")

echo "== the issue's attack: 10,000 poses of 4,096 joints"
read -r status bytes secs < <(sample "$big" '{"start":0,"end":9999,"fps":1}')
echo "HTTP $status in $secs s: $(python3 -c 'import json,sys; p=json.load(open(sys.argv[1])); print(p["code"], "-", p["detail"])' "$IB_WORK/answer")"

echo "== the largest admitted answer of 1,000 joints"
# The refusal of 10,000 poses states the estimate; the per-pose bound gives the largest count admitted.
sample "$wide" '{"start":0,"end":9999,"fps":1}' >/dev/null
n=$(python3 -c '
import json, re, sys
p = json.load(open(sys.argv[1]))
estimate, limit = (int(x) for x in re.search(r"up to (\d+) bytes.* is (\d+)", p["detail"]).groups())
print((limit - 12) // ((estimate - 12) // 10000))' "$IB_WORK/answer")
echo "before: RSS $(rss VmRSS), peak so far $(rss VmHWM)"
read -r status bytes secs < <(sample "$wide" "{\"start\":0,\"end\":$((n - 1)),\"fps\":1}")
echo "$n poses: HTTP $status, $bytes bytes in $secs s; server RSS $(rss VmRSS), peak $(rss VmHWM)"
read -r status _ _ < <(sample "$wide" "{\"start\":0,\"end\":$n,\"fps\":1}")
echo "$((n + 1)) poses: HTTP $status $(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["code"])' "$IB_WORK/answer")"
