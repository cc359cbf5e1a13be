#!/usr/bin/env bash
# Runs the client examples in examples/clients/ against a real server: the
# Python one (REST, gRPC and WebSocket; its compact-frame decoder on the test
# vectors), the Godot one's GDScript parsed and linted (gdtoolkit: no engine
# here), the JavaScript ones (fetch and a
# WebSocket stream with a seek; a graph driven by `set` controls) and the C#
# one (a compact stream read as a game loop would, each pose checked against
# the server's within the error bound). Each checks what it reads and exits non-zero
# on a mismatch; this script fails with it. The C# one needs Mono's `mcs` and
# `mono` (scripts/csharp.sh installs them).
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
ib_workdir
ib_serve clients --data-dir "$IB_WORK/data"

echo "== Python client"
python3 -m venv "$IB_WORK/venv"
"$IB_WORK/venv/bin/pip" install --quiet --disable-pip-version-check -r examples/clients/python/requirements.txt
# The compact-frame decoder against docs/compact-frames/ (numpy comes from the venv).
"$IB_WORK/venv/bin/python" -m unittest discover -s examples/clients/python -p 'test_*.py'
"$IB_WORK/venv/bin/python" examples/clients/python/inbetween_client.py --http "$IB_HTTP" --grpc "$IB_GRPC" examples/wave.json
# The Fox's locomotion graph driven from a loop of `set` controls, its blend weights checked.
"$IB_WORK/venv/bin/python" examples/clients/python/graph.py --http "$IB_HTTP" \
  --import examples/gltf/Fox/Fox.glb examples/graphs/fox-locomotion.json

echo "== Godot client: GDScript 4 syntax and lint (gdtoolkit; no Godot engine here, README in examples/clients/godot)"
"$IB_WORK/venv/bin/pip" install --quiet --disable-pip-version-check gdtoolkit==4.5.0
"$IB_WORK/venv/bin/gdparse" examples/clients/godot/*.gd examples/clients/godot/tests/*.gd >/dev/null
"$IB_WORK/venv/bin/gdlint" examples/clients/godot/*.gd examples/clients/godot/tests/*.gd

echo "== JavaScript client"
node_flags=()
node -e 'process.exit(typeof WebSocket === "undefined" ? 1 : 0)' || node_flags+=(--experimental-websocket)
node "${node_flags[@]}" examples/clients/js/play.mjs --http "$IB_HTTP" examples/wave.json
# The Fox's locomotion graph driven by a scripted loop of `set` controls, its blend weights checked.
node "${node_flags[@]}" examples/clients/js/graph.mjs --http "$IB_HTTP" --script \
  --import examples/gltf/Fox/Fox.glb --file examples/graphs/fox-locomotion.json

echo "== C# client (Mono)"
mcs -langversion:7 -warnaserror -out:"$IB_WORK/StreamCheck.exe" examples/clients/csharp/Compact.cs \
  examples/clients/csharp/InbetweenStream.cs examples/clients/csharp/StreamCheck.cs
# A clip document, and the Fox's first clip imported (a layout whose bound is over max_error).
mono "$IB_WORK/StreamCheck.exe" --http "$IB_HTTP" examples/wave.json
mono "$IB_WORK/StreamCheck.exe" --http "$IB_HTTP" --frames 90 examples/gltf/Fox/Fox.glb
