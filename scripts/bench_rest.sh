#!/usr/bin/env bash
# REST throughput: GET /v1/clips/{id}/pose on a 20-joint clip vs GET /healthz,
# same server, same run, measured with wrk (Debian: apt-get install -y wrk).
# Traffic goes to 127.0.0.1 only. Builds the release binary unless
# INBETWEEN_BIN names one.
#   scripts/bench_rest.sh [seconds] [connections] [rounds]   # defaults 10 32 2
#   scripts/bench_rest.sh --help                             # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
secs=${1:-10}
conns=${2:-32}
rounds=${3:-2}
command -v wrk >/dev/null || { echo "wrk is missing: apt-get install -y wrk" >&2; exit 1; }
ib_bin release
ib_workdir
work=$IB_WORK
ib_serve server --data-dir "$work/data"
pid=$IB_PID base=$IB_HTTP

# A 20-joint chain: every joint has a 31-key Catmull-Rom rotation track, the
# root also a translation track.
python3 - >"$work/clip.json" <<'PY'
import json, math
joints = [{"name": f"j{i}", "parent": (f"j{i-1}" if i else None), "rest": {"translation": [0, 0.1, 0]}} for i in range(20)]
times = [i / 10 for i in range(31)]
def rot(i, k):
    a = 0.3 * math.sin(k / 5 + i)
    return [0, 0, math.sin(a / 2), math.cos(a / 2)]
tracks = [{"joint": f"j{i}", "channel": "rotation", "interpolation": "catmull_rom",
           "times": times, "values": [rot(i, k) for k in range(31)]} for i in range(20)]
tracks.append({"joint": "j0", "channel": "translation", "interpolation": "catmull_rom",
               "times": times, "values": [[k / 10, 0, 0] for k in range(31)]})
print(json.dumps({"name": "bench20", "skeleton": {"joints": joints}, "tracks": tracks, "playback": "loop"}))
PY
id=$(curl -sf -X POST "$base/v1/clips" -H 'Content-Type: application/json' --data-binary @"$work/clip.json" \
     | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
pose="$base/v1/clips/$id/pose?t=1.2345"
curl -sf "$pose" >/dev/null

# Server CPU time per request (from /proc, utime+stime) is reported beside
# wrk's figures: on a shared machine wall-clock throughput swings with other
# load, while the CPU each request costs the server does not.
ticks=$(getconf CLK_TCK)
cpu() { awk '{print $14 + $15}' "/proc/$pid/stat"; }
echo "date: $(date -u +%FT%TZ)  cpus: $(nproc)  load: $(cut -d' ' -f1-3 /proc/loadavg)  wrk -t2 -c$conns -d${secs}s --latency"
for round in $(seq "$rounds"); do
  for url in "$base/healthz" "$pose"; do
    before=$(cpu)
    out=$(wrk -t2 -c"$conns" -d"${secs}s" --latency "$url")
    after=$(cpu)
    rps=$(awk '/^Requests\/sec/ {print $2}' <<<"$out")
    reqs=$(awk '/requests in/ {print $1}' <<<"$out")
    p50=$(awk '$1 == "50%" {print $2}' <<<"$out")
    p99=$(awk '$1 == "99%" {print $2}' <<<"$out")
    non2xx=$(awk '/Non-2xx/ {print $NF}' <<<"$out")
    cpu_us=$(awk -v a="$before" -v b="$after" -v n="$reqs" -v hz="$ticks" 'BEGIN {printf "%.1f", (b - a) / hz * 1e6 / n}')
    printf 'round %s %-8s req/s %10s  p50 %8s  p99 %8s  server-cpu/req %6s us  non-2xx %s\n' "$round" \
      "$([[ $url == *healthz ]] && echo healthz || echo pose)" "$rps" "$p50" "$p99" "$cpu_us" "${non2xx:-0}"
  done
done
