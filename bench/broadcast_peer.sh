#!/usr/bin/env bash
# Broadcasts against a plain Node `ws` broadcaster (BENCHMARKS.md "Broadcasts against a Node `ws` peer"):
# per scenario, the release server and then the peer (bench/peer_ws_broadcast/server.mjs, `ws` pinned in its
# package-lock.json, installed with `npm ci`) under the same `inbetween load ws-broadcast` (one broadcast of the
# generated 20-joint clip, N viewers at F fps, JSON frames). The peer sends one real frame of the server's (taken
# from the server's broadcast of the same clip at the same fps by capture.mjs), its `seq` and
# `sent_at_unix_nanos` stamped per tick, as one buffer to every viewer's socket. Each of the two runs of a
# scenario waits (60 s at a time, up to WAIT_MINUTES) until the 1-minute load average is at most QUIET, warms up
# with 200 viewers for 3 s, then measures; each is its own fresh process. At the end one table: server CPU per
# delivered frame (from /proc/PID/stat over the window, divided by the frames the viewers received in it), its
# ratio to the peer's, loss, receive lateness p50/p99; and the issue's two verdicts: CPU per frame at most the
# peer's, and p99 at most the peer's at 5,000 viewers.
#
#   bench/broadcast_peer.sh                        # 1000x30 and 5000x30, 20-second windows
#   SCENARIOS="5000x30" bench/broadcast_peer.sh    # VIEWERSxFPS pairs
#   SECS=5 SCENARIOS="300x30" bench/broadcast_peer.sh   # a small smoke run
#   JOINTS=64                                      # the clip's joints (default 20)
#   QUIET=1.5 WAIT_MINUTES=10                      # the load average to wait for, and how long (defaults)
#   INBETWEEN_BIN=path bench/broadcast_peer.sh     # a release binary built elsewhere
#   OUT=dir                                        # keep the reports there (default: a temporary directory)
#   bench/broadcast_peer.sh --help                 # this text
#
# Needs node (20 or later) and npm; npm reaches only the npm registry, into bench/peer_ws_broadcast/node_modules.
set -euo pipefail
source "$(dirname "$0")/streams_lib.sh"
ib_help "$@"
peer_dir=$IB_ROOT/bench/peer_ws_broadcast
(cd "$peer_dir" && npm ci --no-audit --no-fund --loglevel=error)
bs_serve
echo "file descriptors: soft limit $(ulimit -n) (hard $(ulimit -Hn)) per process; node $(node --version)"

# NAME FRAME: stops the current server or peer and starts the peer sending FRAME: pid, http, grpc.
peer_serve() {
  local _
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  node "$peer_dir/server.mjs" --frame "$2" >"$IB_WORK/$1.out" 2>"$IB_WORK/$1.err" &
  pid=$!
  IB_PIDS+=("$pid")
  for _ in $(seq 100); do
    grep -q "gRPC listening" "$IB_WORK/$1.out" 2>/dev/null && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  http=$(sed -n 's/^peer listening on //p' "$IB_WORK/$1.out")
  grpc=$(sed -n 's/^peer gRPC listening on //p' "$IB_WORK/$1.out")
  if [ -z "$http" ] || [ -z "$grpc" ]; then
    echo "the peer ($1) did not start:" >&2
    cat "$IB_WORK/$1.err" >&2
    exit 1
  fi
  echo "peer pid $pid, $http, $grpc"
}

scenarios=()
for scenario in ${SCENARIOS:-1000x30 5000x30}; do
  viewers=$(bs_viewers "${scenario%x*}") fps=${scenario#*x}
  name=$viewers-at-$fps
  common=(ws-broadcast --fps "$fps" --joints "${JOINTS:-20}")
  bs_fresh_server "server-$name"
  bs_run "warm-server-$name" "${common[@]}" -c 200 -d 3
  bs_run --now "server-$name" "${common[@]}" -c "$viewers" -d "${SECS:-20}"
  # The frame the peer sends: one of the server's broadcast of the clip the load uploaded, at the same fps.
  clip=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["clip_id"])' "$out/warm-server-$name.json")
  node "$peer_dir/capture.mjs" --http "$http" --clip "$clip" --fps "$fps" --out "$out/$name.frame"
  peer_serve "peer-$name" "$out/$name.frame"
  bs_run "warm-peer-$name" "${common[@]}" -c 200 -d 3
  bs_run --now "peer-$name" "${common[@]}" -c "$viewers" -d "${SECS:-20}"
  curl -s "$http/metrics" >"$out/peer-$name.metrics" || true
  scenarios+=("$name")
done

echo "== broadcasts: the server against a plain Node \`ws\` broadcaster (the issue: CPU per frame ≤ the peer's; p99 ≤ the peer's at 5,000)"
python3 - "$out" "${scenarios[@]}" <<'PY'
import json, os, sys
out, names = sys.argv[1], sys.argv[2:]
nan = float("nan")
def load(name):
    p = os.path.join(out, name + ".json")
    if not os.path.exists(p):
        return None
    r = json.load(open(p)); s = r["streams"]; srv = r.get("server") or {}
    return {"opened": s["opened"], "streams": s["streams"], "fps": s["frames_per_stream_per_sec"],
            "cores": srv.get("cpu_cores", nan), "us": srv.get("cpu_us_per_op", nan),
            "kib": nan if srv.get("rss_per_stream_bytes") is None else srv["rss_per_stream_bytes"] / 1024,
            "loss": s["loss_ratio"],
            "p50": s["receive_lateness"]["p50_us"] / 1e3, "p99": s["receive_lateness"]["p99_us"] / 1e3,
            "client": r.get("client_cpu_cores") or nan, "errors": r["errors"] or "none",
            "load": open(os.path.join(out, name + ".loadavg0")).read().split()[0]}
ok = lambda b: "met" if b else "MISSED"
print("| scenario | run | viewers opened | frames/s each | CPU per delivered frame | server / peer | cores (client) | loss | receive late p50 / p99 | RSS per viewer | load avg before |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
verdicts = []
for n in names:
    server, peer = load("server-" + n), load("peer-" + n)
    ratio = server["us"] / peer["us"] if server and peer and peer["us"] > 0 else nan
    for who, run, r in (("server", "server", server), ("Node `ws` peer", "peer", peer)):
        if r is None:
            print("| %s | %s | (failed: see %s-%s.err) |" % (n, who, run, n)); continue
        print("| %s | %s | %d/%d | %.2f | %.2f µs | %s | %.2f (%.2f) | %.3f %% | %.1f / %.1f ms | %.1f KiB | %s |" % (
            n, who, r["opened"], r["streams"], r["fps"], r["us"], "×%.2f" % ratio if who == "server" else "",
            r["cores"], r["client"], 100 * r["loss"], r["p50"], r["p99"], r["kib"], r["load"]))
    if not (server and peer):
        continue
    # A run whose viewers were closed or refused did not carry its viewers for the window: no verdict on it.
    failed = ["%s errors %s" % (who, r["errors"]) for who, r in (("server", server), ("peer", peer)) if r["errors"] != "none"]
    judge = lambda b: "NOT JUDGED (%s)" % "; ".join(failed) if failed else ok(b)
    verdicts.append("%s: CPU per frame ×%.2f the peer's: %s" % (n, ratio, judge(ratio <= 1)))
    if n.startswith("5000-"):
        verdicts.append("%s: p99 %.1f ms against the peer's %.1f ms: %s" % (
            n, server["p99"], peer["p99"], judge(server["p99"] <= peer["p99"])))
print()
for v in verdicts:
    print("- " + v)
PY
echo "reports: $out"
