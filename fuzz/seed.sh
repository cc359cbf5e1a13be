#!/usr/bin/env bash
# Seeds fuzz/corpus/<target>/ from ../shared/testdata (copied at run time,
# never committed: the files are third-party). Large files are cut down so
# each run stays fast: BVH takes keep their hierarchy and 3 frames, the
# external-buffer glTF gets its .bin embedded as a data: URI.
#
#   fuzz/seed.sh            # uses $CARGO_TARGET_DIR/debug/inbetween (or ../target) if built
#   fuzz/seed.sh --help     # this text
set -euo pipefail
source "$(dirname "$0")/../scripts/lib.sh"
ib_help "$@"
cd "$IB_ROOT/fuzz"
T=../../shared/testdata
mkdir -p corpus/import_gltf corpus/import_bvh corpus/clip_json corpus/import_evaluate corpus/motion_json corpus/graph_json
# The hardening corpus (committed, our own files) and past findings seed every target too.
C=../tests/corpus
for set in valid malformed; do
  cp "$C/$set"/gltf/* "$C/$set"/glb/* corpus/import_gltf/
  cp "$C/$set"/bvh/* corpus/import_bvh/
  cp "$C/$set"/json/* corpus/clip_json/
  cp "$C/$set"/*/* corpus/import_evaluate/ 2>/dev/null || true
done
rm -f corpus/import_evaluate/*.http corpus/import_evaluate/*.bin
for t in import_gltf import_bvh clip_json import_evaluate motion_json graph_json; do
  cp corpus-min/$t/* regressions/$t/* corpus/$t/ 2>/dev/null || true
done
cp "$T"/gltf/AnimatedTriangle/*.gltf "$T"/gltf/BoxAnimated/*.gltf "$T"/gltf/RiggedSimple/*.gltf \
   "$T"/gltf/Fox/Fox.glb corpus/import_gltf/
python3 - "$T" <<'PY'
import base64, json, sys
t = sys.argv[1]
d = json.load(open(f"{t}/gltf/InterpolationTest/InterpolationTest.gltf"))
b = open(f"{t}/gltf/InterpolationTest/interpolation.bin", "rb").read()
d["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(b).decode()
json.dump(d, open("corpus/import_gltf/InterpolationTest-embedded.gltf", "w"))
for name in ["131_01", "131_03", "05_20-mb", "05_20-daz"]:
    lines = open(f"{t}/bvh/{name}.bvh", "rb").read().split(b"\n")
    m = next(i for i, l in enumerate(lines) if l.strip().upper() == b"MOTION")
    head = lines[: m + 1] + [b"Frames: 3", lines[m + 2]] + lines[m + 3 : m + 6]
    open(f"corpus/import_bvh/{name}-3frames.bvh", "wb").write(b"\n".join(head) + b"\n")
PY
cp ../examples/*.json corpus/clip_json/
BIN=${CARGO_TARGET_DIR:-../target}/debug/inbetween
if [ -x "$BIN" ]; then
  for f in "$T"/gltf/AnimatedTriangle/*.gltf "$T"/gltf/BoxAnimated/*.gltf "$T"/gltf/RiggedSimple/*.gltf \
           corpus/import_gltf/InterpolationTest-embedded.gltf corpus/import_bvh/131_01-3frames.bvh; do
    "$BIN" import "$f" | python3 -c '
import json, sys
d = json.load(sys.stdin)
for i, c in enumerate(d["clips"]):
    json.dump(c, open(f"corpus/clip_json/{sys.argv[1]}-{i}.json", "w"))
' "$(basename "$f")"
  done
fi
# One cp per source: files named by their content hash may be in several.
for d in import_gltf import_bvh clip_json; do cp -f corpus/$d/* corpus/import_evaluate/; done
for t in corpus/*; do echo "$t: $(ls "$t" | wc -l) files"; done
