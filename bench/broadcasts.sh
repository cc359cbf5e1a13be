#!/usr/bin/env bash
# Broadcasts (issue 19; BENCHMARKS.md "Broadcasts (issue 19)"): WebSocket
# viewers of one broadcast (`inbetween load ws-broadcast`: `POST
# /v1/broadcasts` of the generated chain clip, then N viewers of
# `/v1/broadcasts/{id}/stream`), the issue's two scenarios — 20,000 viewers at
# 10 fps and 5,000 at 30 fps — each on a fresh release server on loopback,
# load generator on the same machine (servers take --max-connections,
# --max-streams and --max-streams-per-client 40000). Per scenario: a wait (60 s at a time, up
# to WAIT_MINUTES) until the 1-minute load average is at most QUIET, a short
# warm-up run of 200 viewers (so the measured run's "RSS before" is a warmed
# server's), then the measured run; each run's summary and /metrics are kept
# in $OUT. At the end, a table against the issue's targets: loss ≤ 0.1 %, p99
# receive lateness ≤ 50 ms, server RSS per viewer ≤ 16 KiB.
#
# File descriptors: the server and the generator each hold one per viewer (and
# a few hundred more), so the script raises the soft limit (to 65536 when
# allowed, else the hard limit) and runs at most limit − 256 viewers, saying so.
#
#   bench/broadcasts.sh                       # both scenarios, JSON frames, 20-second windows
#   ENCODINGS="ws wspb" bench/broadcasts.sh   # also protobuf frames (ws: JSON, wspb: protobuf)
#   SCENARIOS="5000x30" bench/broadcasts.sh   # VIEWERSxFPS pairs (default "20000x10 5000x30")
#   SECS=5 SCENARIOS="300x10" bench/broadcasts.sh   # a small smoke run
#   JOINTS=64 bench/broadcasts.sh             # the clip's joints (default 20)
#   QUIET=1.5 WAIT_MINUTES=10                 # the load average to wait for, and how long (defaults)
#   INBETWEEN_BIN=path bench/broadcasts.sh    # a binary built elsewhere
#   bench/broadcasts.sh --help                # this text
set -euo pipefail
source "$(dirname "$0")/streams_lib.sh"
ib_help "$@"
bs_serve
echo "file descriptors: soft limit $(ulimit -n) (hard $(ulimit -Hn)) per process"

runs=()
for scenario in ${SCENARIOS:-20000x10 5000x30}; do
  viewers=$(bs_viewers "${scenario%x*}") fps=${scenario#*x}
  for enc in ${ENCODINGS:-ws}; do
    case $enc in
      ws) flags=() ;;
      wspb) flags=(--protobuf) ;;
      *) echo "unknown encoding $enc (ws, wspb)" >&2; exit 2 ;;
    esac
    name=$enc-$viewers-at-$fps
    bs_fresh_server "server-$name"
    common=(ws-broadcast "${flags[@]}" --fps "$fps" --joints "${JOINTS:-20}")
    bs_run "warm-$name" "${common[@]}" -c 200 -d 3
    bs_run --now "$name" "${common[@]}" -c "$viewers" -d "${SECS:-20}"
    curl -s "$http/metrics" >"$out/$name.metrics" || true
    runs+=("$name")
  done
done

echo "== broadcasts against the issue's targets (loss ≤ 0.1 %, p99 receive lateness ≤ 50 ms, RSS ≤ 16 KiB per viewer)"
python3 - "$out" "${runs[@]}" <<'PY'
import json, os, sys
out, names = sys.argv[1], sys.argv[2:]
ok = lambda b: "met" if b else "MISSED"
print("| run | viewers opened | fps | frames/s each | receive late p50 / p99 / max | loss | server CPU | RSS before → after | RSS per viewer | load avg before |")
print("|---|---|---|---|---|---|---|---|---|---|")
for n in names:
    p = os.path.join(out, n + ".json")
    if not os.path.exists(p):
        print("| %s | (failed: see %s.err) |" % (n, n)); continue
    r = json.load(open(p)); s = r["streams"]; l = s["receive_lateness"]; srv = r.get("server") or {}
    kib = (srv.get("rss_per_stream_bytes") or float("nan")) / 1024
    print("| %s | %d/%d | %d | %.2f | %.1f / %.1f / %.1f ms | %.3f %% (%s; %d gaps, %d dropped) | %.2f cores, %.2f µs/frame | %.0f → %.0f MiB | %.1f KiB (%s) | %s |" % (
        n, s["opened"], s["streams"], s["fps"], s["frames_per_stream_per_sec"],
        l["p50_us"] / 1e3, l["p99_us"] / 1e3, l["max_us"] / 1e3,
        100 * s["loss_ratio"], ok(s["loss_ratio"] <= 0.001), s["gaps"], s["dropped"],
        srv.get("cpu_cores", float("nan")), srv.get("cpu_us_per_op", float("nan")),
        srv.get("rss_before_bytes", 0) / 2**20, srv.get("rss_end_bytes", 0) / 2**20, kib, ok(kib <= 16),
        open(os.path.join(out, n + ".loadavg0")).read().split()[0]))
    print("|  | p99 %s; client %.2f cores; errors %s | | | | | | | | |" % (
        ok(l["p99_us"] <= 50_000), r.get("client_cpu_cores") or -1, r["errors"] or "none"))
PY
echo "reports: $out"
