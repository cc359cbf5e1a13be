#!/usr/bin/env bash
# Runs the client examples in examples/clients/ against a real server: the
# Python one (REST, gRPC and WebSocket) and the JavaScript one (fetch and a
# WebSocket stream with a seek). Each checks what it reads and exits non-zero
# on a mismatch; this script fails with it.
#
#   scripts/clients.sh          # builds the debug binary, a venv for Python
#   scripts/clients.sh --help   # this text
#
# INBETWEEN_BIN: a binary built elsewhere. The Python packages
# (examples/clients/python/requirements.txt) go into a virtualenv under the
# work directory; nothing is installed system-wide.
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"

ib_bin debug
ib_serve clients --data-dir "$IB_WORK/data"

echo "== Python client"
python3 -m venv "$IB_WORK/venv"
"$IB_WORK/venv/bin/pip" install --quiet --disable-pip-version-check -r examples/clients/python/requirements.txt
"$IB_WORK/venv/bin/python" examples/clients/python/inbetween_client.py --http "$IB_HTTP" --grpc "$IB_GRPC" examples/wave.json

echo "== JavaScript client"
node_flags=()
node -e 'process.exit(typeof WebSocket === "undefined" ? 1 : 0)' || node_flags+=(--experimental-websocket)
node "${node_flags[@]}" examples/clients/js/play.mjs --http "$IB_HTTP" examples/wave.json
