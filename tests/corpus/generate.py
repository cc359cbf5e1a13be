#!/usr/bin/env python3
"""Writes the hardening corpus: malformed and valid inputs, one small file each.

Deterministic (no randomness, no clock): running it again rewrites the same
bytes. The files are committed, so the replay (`cargo test --test
hardening`) never depends on this script; it is here so the corpus can be
read, reviewed and extended. The expected outcome of each malformed file is
in `index.tsv`; `INBETWEEN_CORPUS_RECORD=1 cargo test --test service hardening
corpus` fills in the exact statuses the server gave, for review, keeping
the class this script wrote (a 4xx, or a gRPC client-error code).

Layout: malformed/<area>/<name>, valid/<area>/<name>, where the area says
how the file is sent:
  json        POST /v1/clips (application/json)
  gltf, glb   POST /v1/clips/import?format=gltf|glb
  bvh         POST /v1/clips/import?format=bvh
  sniff       POST /v1/clips/import (no format: sniffed from the bytes)
  http        the file is a whole HTTP/1.1 request, sent as it is
  grpc        <Method>.<name>.bin: a gRPC request body (length-prefixed
              messages) sent to /inbetween.v1.Animation/<Method>
`@@@@@@@@-@@@@-@@@@-@@@@-@@@@@@@@@@@@` in http and grpc files is replaced by
the id of a stored clip (same length, so lengths stay right).
"""

import base64
import json
import os
import shutil
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
CLIP_ID = "@@@@@@@@-@@@@-@@@@-@@@@-@@@@@@@@@@@@"
MISSING_ID = "00000000-0000-7000-8000-000000000000"

files = []  # (relative path, expected)


def write(kind, area, name, data, expect):
    if isinstance(data, str):
        data = data.encode()
    files.append((f"{kind}/{area}/{name}", data, expect))


# Inputs once thought malformed that the server rightly accepts: each is well defined (a single key, huge
# but finite values, unused or unknown parts, BVH angles wrapping, names with odd bytes). Kept as valid files.
TOLERATED = {"single-key-catmull.json", "values-f32-max-sum.gltf", "asset-version-1.gltf",
             "mesh-position-missing.gltf", "extensions-required.gltf", "second-buffer-no-uri.glb",
             "rotation-1e30.bvh", "frame-time-tiny.bvh", "frame-time-huge.bvh", "nul-bytes.bvh",
             "invalid-utf8-name.bvh"}


def bad(area, name, data, expect="4xx"):
    if name in TOLERATED:
        return good(area, "tolerated-" + name, data)
    write("malformed", area, f"{sum(1 for f in files if f[0].startswith('malformed/' + area + '/')):03}-{name}", data, expect)


def good(area, name, data):
    write("valid", area, name, data, "2xx")


def dumps(v):
    return json.dumps(v, separators=(",", ":"))


# ---------------------------------------------------------------- JSON clips

WAVE = {
    "name": "wave",
    "skeleton": {"joints": [
        {"name": "root", "parent": None},
        {"name": "arm", "parent": "root", "rest": {"translation": [0, 1, 0]}},
    ]},
    "tracks": [
        {"joint": "root", "channel": "translation", "interpolation": "catmull_rom",
         "times": [0, 1, 2, 3], "values": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]},
        {"joint": "arm", "channel": "rotation", "interpolation": "catmull_rom", "ends": "reflect",
         "times": [0, 1.5, 3], "values": [[0, 0, 0, 1], [0, 0, 0.3826834, 0.9238795], [0, 0, 0, 1]]},
    ],
    "events": [{"time": 1.0, "name": "footstep"}],
    "playback": "loop",
}


def wave(edit):
    d = json.loads(json.dumps(WAVE))
    edit(d)
    return dumps(d)


def setp(path, value):
    """An edit that sets d[path...] = value."""
    def edit(d):
        node = d
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return edit


def delp(path):
    def edit(d):
        node = d
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]
    return edit


RAW_JSON = [
    ("empty", b""),
    ("whitespace", b"   \n\t "),
    ("open-brace", b"{"),
    ("array", b"[]"),
    ("null", b"null"),
    ("number", b"42"),
    ("string", b'"wave"'),
    ("true", b"true"),
    ("trailing-comma", dumps(WAVE)[:-1].encode() + b",}"),
    ("truncated-half", dumps(WAVE)[: len(dumps(WAVE)) // 2].encode()),
    ("truncated-last-byte", dumps(WAVE)[:-1].encode()),
    ("unclosed-string", b'{"name": "wave'),
    ("invalid-utf8-name", b'{"name": "\xff\xfe", "tracks": []}'),
    ("invalid-utf8-key", b'{"\xc3\x28": 1}'),
    ("lone-surrogate-escape", b'{"name": "\\ud800", "tracks": []}'),
    ("bad-escape", b'{"name": "\\q", "tracks": []}'),
    ("nul-byte", b'{"name": "w\x00", "tracks": []}'),
    ("nested-arrays-10000", b"[" * 10000 + b"]" * 10000),
    ("nested-objects-5000", b'{"a":' * 5000 + b"1" + b"}" * 5000),
    ("comment", b'/* c */ ' + dumps(WAVE).encode()),
    ("single-quotes", dumps(WAVE).replace('"', "'").encode()),
    ("nan-literal", dumps(WAVE).replace("[1,0,0]", "[NaN,0,0]").encode()),
    ("infinity-literal", dumps(WAVE).replace("[1,0,0]", "[Infinity,0,0]").encode()),
    ("minus-infinity-literal", dumps(WAVE).replace("[1,0,0]", "[-Infinity,0,0]").encode()),
    ("number-1e400", dumps(WAVE).replace("[1,0,0]", "[1e400,0,0]").encode()),
    ("number-hex", dumps(WAVE).replace("[1,0,0]", "[0x10,0,0]").encode()),
    ("number-leading-zero", dumps(WAVE).replace("[1,0,0]", "[01,0,0]").encode()),
    ("two-documents", dumps(WAVE).encode() + dumps(WAVE).encode()),
    ("trailing-garbage", dumps(WAVE).encode() + b"x"),
    ("utf16-le", dumps(WAVE).encode("utf-16-le")),
    ("duplicate-key-name", b'{"name":"a","name":"b","tracks":[]}'),
    ("huge-string-escape", b'{"name":"' + b"\\u0041" * 2000 + b'","tracks":[]}'),
]
for name, data in RAW_JSON:
    bad("json", name + ".json", data)

EDITS = [
    ("missing-name", delp(["name"])),
    ("missing-tracks", delp(["tracks"])),
    ("empty-tracks", setp(["tracks"], [])),
    ("empty-name", setp(["name"], "")),
    ("name-257-chars", setp(["name"], "n" * 257)),
    ("name-number", setp(["name"], 7)),
    ("unknown-top-field", setp(["extra"], 1)),
    ("tracks-object", setp(["tracks"], {})),
    ("track-null", setp(["tracks", 0], None)),
    ("unknown-track-field", setp(["tracks", 0, "weight"], 1)),
    ("unknown-channel", setp(["tracks", 0, "channel"], "weights")),
    ("unknown-interpolation", setp(["tracks", 0, "interpolation"], "bspline")),
    ("interpolation-case", setp(["tracks", 0, "interpolation"], "LINEAR")),
    ("unknown-ends", setp(["tracks", 1, "ends"], "mirror")),
    ("ends-on-linear", lambda d: (d["tracks"][0].update(interpolation="linear", ends="wrap"))),
    ("unknown-playback", setp(["playback"], "bounce")),
    ("unknown-joint", setp(["tracks", 0, "joint"], "leg")),
    ("empty-joint-name", setp(["tracks", 0, "joint"], "")),
    ("times-not-increasing", setp(["tracks", 0, "times"], [0, 2, 1, 3])),
    ("times-equal", setp(["tracks", 0, "times"], [0, 1, 1, 3])),
    ("times-decreasing", setp(["tracks", 0, "times"], [3, 2, 1, 0])),
    ("times-strings", setp(["tracks", 0, "times"], ["0", "1", "2", "3"])),
    ("times-null-entry", setp(["tracks", 0, "times"], [0, None, 2, 3])),
    ("times-f32-overflow", setp(["tracks", 0, "times"], [0, 1, 2, 1e39])),
    ("times-fewer-than-values", setp(["tracks", 0, "times"], [0, 1, 2])),
    ("times-more-than-values", setp(["tracks", 0, "times"], [0, 1, 2, 3, 4])),
    ("no-keys", lambda d: d["tracks"][0].update(times=[], values=[])),
    ("value-two-floats", setp(["tracks", 0, "values", 1], [1, 0])),
    ("value-four-floats-translation", setp(["tracks", 0, "values", 1], [1, 0, 0, 0])),
    ("value-three-floats-rotation", setp(["tracks", 1, "values", 1], [0, 0, 1])),
    ("value-f32-overflow", setp(["tracks", 0, "values", 1], [3.5e38, 0, 0])),
    ("value-string", setp(["tracks", 0, "values", 1], ["1", "0", "0"])),
    ("value-nested", setp(["tracks", 0, "values", 1], [[1], 0, 0])),
    ("values-flat", setp(["tracks", 0, "values"], [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0])),
    ("zero-quaternion", setp(["tracks", 1, "values", 1], [0, 0, 0, 0])),
    ("tiny-quaternion", setp(["tracks", 1, "values", 1], [1e-30, 0, 0, 0])),
    ("tension-out-of-range", setp(["tracks", 0, "tension"], 7)),
    ("tension-negative", setp(["tracks", 0, "tension"], -1)),
    ("tension-on-linear", lambda d: d["tracks"][0].update(interpolation="linear", tension=0.5)),
    ("hermite-without-tangents", setp(["tracks", 0, "interpolation"], "cubic_hermite")),
    ("hermite-short-tangents", lambda d: d["tracks"][0].update(
        interpolation="cubic_hermite", in_tangents=[[0, 0, 0]], out_tangents=[[0, 0, 0]])),
    ("tangents-on-linear", lambda d: d["tracks"][0].update(
        interpolation="linear", in_tangents=[[0, 0, 0]] * 4, out_tangents=[[0, 0, 0]] * 4)),
    ("constant-speed-rotation", setp(["tracks", 1, "speed"], "constant")),
    ("unknown-speed", setp(["tracks", 0, "speed"], "fast")),
    ("duplicate-track", lambda d: d["tracks"].append(json.loads(json.dumps(d["tracks"][0])))),
    ("duplicate-joint", lambda d: d["skeleton"]["joints"].append({"name": "arm", "parent": "root"})),
    ("unknown-parent", setp(["skeleton", "joints", 1, "parent"], "spine")),
    ("self-parent", setp(["skeleton", "joints", 1, "parent"], "arm")),
    ("parent-after-child", lambda d: d["skeleton"]["joints"].reverse()),
    ("parent-cycle", lambda d: d["skeleton"]["joints"].__setitem__(0, {"name": "root", "parent": "arm"})),
    ("empty-skeleton", setp(["skeleton", "joints"], [])),
    ("rest-nan-string", setp(["skeleton", "joints", 1, "rest", "translation"], ["NaN", 0, 0])),
    ("rest-two-floats", setp(["skeleton", "joints", 1, "rest", "translation"], [0, 1])),
    ("rest-zero-rotation", setp(["skeleton", "joints", 1, "rest", "rotation"], [0, 0, 0, 0])),
    ("rest-overflow-scale", setp(["skeleton", "joints", 1, "rest", "scale"], [1e39, 1, 1])),
    ("rest-unknown-field", setp(["skeleton", "joints", 1, "rest", "skew"], [0, 0, 0])),
    ("inverse-bind-short", setp(["skeleton", "joints", 1, "inverse_bind"], [1, 0, 0])),
    ("joint-name-empty", setp(["skeleton", "joints", 1, "name"], "")),
    ("event-time-overflow", setp(["events", 0, "time"], 1e39)),
    ("event-name-missing", delp(["events", 0, "name"])),
    ("event-unknown-field", setp(["events", 0, "data"], {})),
    ("events-object", setp(["events"], {"time": 1})),
    ("single-key-catmull", lambda d: d["tracks"][0].update(times=[0], values=[[0, 0, 0]])),
]
for name, edit in EDITS:
    bad("json", name + ".json", wave(edit))


def many_tracks(n):
    return dumps({"name": "many", "tracks": [
        {"joint": f"j{i}", "channel": "translation", "interpolation": "step", "times": [0], "values": [[0, 0, 0]]}
        for i in range(n)]})


# The replay server runs with max_tracks 64, max_joints 64, max_keys_per_track 1000 and a 256 KiB body
# limit (see tests/hardening).
bad("json", "tracks-over-limit.json", many_tracks(65))
bad("json", "keys-over-limit.json", dumps({"name": "keys", "tracks": [
    {"joint": "j", "channel": "translation", "interpolation": "linear",
     "times": list(range(1001)), "values": [[0, 0, 0]] * 1001}]}))
bad("json", "joints-over-limit.json", dumps({"name": "joints", "skeleton": {"joints": [
    {"name": f"j{i}", "parent": None} for i in range(65)]},
    "tracks": [{"joint": "j0", "channel": "scale", "interpolation": "step", "times": [0], "values": [[1, 1, 1]]}]}))


# Numbers that would overflow f32 (issue 15): refused at build with a code naming the field.
def line(times, joint="a"):
    return {"joint": joint, "channel": "translation", "interpolation": "linear", "times": times,
            "values": [[0, 0, 0], [1, 0, 0]]}


good("json", "subnormal-constant-speed.json", dumps({"name": "subnormal", "tracks": [
    {"joint": "a", "channel": "translation", "interpolation": "linear", "speed": "constant",
     "times": [0, 1e-45, 3e-45, 1], "values": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 1]]}]}))
bad("json", "duration-past-f32.json", dumps({"name": "wide", "tracks": [line([-3.4e38, 3.4e38])]}), "422")
bad("json", "scale-chain-past-f32.json", dumps({"name": "deep", "skeleton": {"joints": [
    {"name": f"j{i}", "parent": f"j{i - 1}" if i else None, "rest": {"translation": [1, 0, 0], "scale": [1.1] * 3}}
    for i in range(60)] + [
    {"name": f"k{i}", "parent": f"k{i - 1}" if i else "j59", "rest": {"scale": [1e30] * 3}} for i in range(2)]},
    "tracks": [line([0, 1], "j0")]}), "422")
bad("json", "hermite-tangent-past-f32.json", dumps({"name": "steep", "tracks": [
    {"joint": "a", "channel": "translation", "interpolation": "cubic_hermite", "times": [0, 100],
     "values": [[0, 0, 0], [0, 0, 0]], "in_tangents": [[0, 0, 0], [0, 0, 0]],
     "out_tangents": [[3e38, 3e38, 3e38], [0, 0, 0]]}]}), "422")
# Joint names are capped at 256 characters (issue 15: every answer repeats them).
bad("json", "joint-name-257-chars.json", dumps({"name": "long", "tracks": [line([0, 1], "ü" * 257)]}), "422")
bad("json", "skeleton-joint-name-257-chars.json", dumps({"name": "long", "skeleton": {"joints": [
    {"name": "j" * 257}]}, "tracks": [line([0, 1], "j" * 257)]}), "422")

# ---------------------------------------------------------------- glTF


def b64uri(data):
    return "data:application/octet-stream;base64," + base64.b64encode(data).decode()


def floats(values):
    return struct.pack(f"<{len(values)}f", *values)


def mini():
    """Node 0 translated by a 2-key LINEAR animation; buffer: times then values."""
    data = floats([0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0])
    return {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "box"}],
        "buffers": [{"byteLength": 32, "uri": b64uri(data)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 8},
            {"buffer": 0, "byteOffset": 8, "byteLength": 24},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]},
            {"bufferView": 1, "componentType": 5126, "count": 2, "type": "VEC3"},
        ],
        "animations": [{
            "name": "move",
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
            "samplers": [{"input": 0, "output": 1, "interpolation": "LINEAR"}],
        }],
    }


def gltf(edit=None):
    d = mini()
    if edit:
        edit(d)
    return dumps(d)


def with_buffer(data, views=None):
    """Replaces buffer 0 with `data` (byteLength = its length)."""
    def edit(d):
        d["buffers"][0] = {"byteLength": len(data), "uri": b64uri(data)}
        if views:
            d["bufferViews"] = views
    return edit


def deep_nodes(depth):
    def edit(d):
        d["nodes"] = [{"children": [i + 1]} if i + 1 < depth else {} for i in range(depth)]
        d["animations"][0]["channels"][0]["target"]["node"] = depth - 1
    return edit


GLTF_EDITS = [
    ("uri-percent-ff", setp(["buffers", 0, "uri"], "%FF")),
    ("uri-percent-truncated", setp(["buffers", 0, "uri"], "buf%2")),
    ("uri-file-scheme", setp(["buffers", 0, "uri"], "file:///etc/passwd")),
    ("uri-dotdot", setp(["buffers", 0, "uri"], "../../../../etc/passwd")),
    ("uri-dotdot-encoded", setp(["buffers", 0, "uri"], "..%2F..%2Fetc%2Fpasswd")),
    ("uri-http", setp(["buffers", 0, "uri"], "http://169.254.169.254/latest/meta-data")),
    ("uri-https", setp(["buffers", 0, "uri"], "https://example.com/a.bin")),
    ("uri-absolute-path", setp(["buffers", 0, "uri"], "/etc/passwd")),
    ("uri-windows-path", setp(["buffers", 0, "uri"], "C:\\Windows\\win.ini")),
    ("uri-plain-name", setp(["buffers", 0, "uri"], "animation.bin")),
    ("uri-empty", setp(["buffers", 0, "uri"], "")),
    ("uri-data-no-comma", setp(["buffers", 0, "uri"], "data:application/octet-stream;base64")),
    ("uri-data-bad-base64", setp(["buffers", 0, "uri"], "data:application/octet-stream;base64,!!!!")),
    ("uri-data-percent-ff", setp(["buffers", 0, "uri"], "data:application/octet-stream,%FF%FF")),
    ("uri-data-short", setp(["buffers", 0, "uri"], "data:application/octet-stream;base64,AAAA")),
    ("uri-number", setp(["buffers", 0, "uri"], 5)),
    ("no-uri-no-glb", delp(["buffers", 0, "uri"])),
    ("bytelength-u64-max", setp(["buffers", 0, "byteLength"], 18446744073709551615)),
    ("bytelength-over-u64", setp(["buffers", 0, "byteLength"], 18446744073709551616)),
    ("bytelength-negative", setp(["buffers", 0, "byteLength"], -1)),
    ("bytelength-float", setp(["buffers", 0, "byteLength"], 32.5)),
    ("bytelength-larger-than-data", setp(["buffers", 0, "byteLength"], 64)),
    ("view-offset-past-buffer", setp(["bufferViews", 1, "byteOffset"], 4096)),
    ("view-length-past-buffer", setp(["bufferViews", 1, "byteLength"], 1 << 31)),
    ("view-offset-u64-max", setp(["bufferViews", 1, "byteOffset"], 18446744073709551615)),
    ("view-stride-3", setp(["bufferViews", 1, "byteStride"], 3)),
    ("view-stride-huge", setp(["bufferViews", 1, "byteStride"], 252)),
    ("view-buffer-missing", setp(["bufferViews", 1, "buffer"], 9)),
    ("accessor-count-huge", setp(["accessors", 1, "count"], 4000000000)),
    ("accessor-count-u64-max", setp(["accessors", 1, "count"], 18446744073709551615)),
    ("accessor-count-zero", setp(["accessors", 0, "count"], 0)),
    ("accessor-count-mismatch", setp(["accessors", 1, "count"], 1)),
    ("accessor-input-count-huge", setp(["accessors", 0, "count"], 2000000000)),
    ("accessor-offset-past-view", setp(["accessors", 1, "byteOffset"], 20)),
    ("accessor-offset-misaligned", setp(["accessors", 1, "byteOffset"], 1)),
    ("accessor-bad-component-type", setp(["accessors", 1, "componentType"], 5130)),
    ("accessor-int-times", setp(["accessors", 0, "componentType"], 5125)),
    ("accessor-bad-type", setp(["accessors", 1, "type"], "VEC7")),
    ("accessor-vec2-translation", setp(["accessors", 1, "type"], "VEC2")),
    ("accessor-view-missing", setp(["accessors", 1, "bufferView"], 7)),
    ("accessor-no-view", delp(["accessors", 1, "bufferView"])),
    ("sparse-count-huge", setp(["accessors", 1, "sparse"], {
        "count": 4000000000, "indices": {"bufferView": 0, "componentType": 5125},
        "values": {"bufferView": 1}})),
    ("sparse-no-view-huge-count", lambda d: d["accessors"][1].update(
        bufferView=None, count=100000000, sparse={"count": 1, "indices": {"bufferView": 0, "componentType": 5125},
                                                   "values": {"bufferView": 1}})),
    ("times-decreasing", with_buffer(floats([1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]))),
    ("times-equal", with_buffer(floats([1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]))),
    ("times-nan", with_buffer(floats([0.0, float("nan"), 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]))),
    ("times-inf", with_buffer(floats([0.0, float("inf"), 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]))),
    ("values-nan", with_buffer(floats([0.0, 1.0, 0.0, float("nan"), 0.0, 1.0, 2.0, 3.0]))),
    ("values-inf", with_buffer(floats([0.0, 1.0, 0.0, 0.0, float("-inf"), 1.0, 2.0, 3.0]))),
    ("values-f32-max-sum", with_buffer(floats([0.0, 1.0, 3.4e38, 3.4e38, 3.4e38, -3.4e38, -3.4e38, -3.4e38]))),
    ("node-cycle-self", setp(["nodes", 0, "children"], [0])),
    ("node-cycle-two", lambda d: d.update(nodes=[{"name": "a", "children": [1]}, {"name": "b", "children": [0]}])),
    ("node-two-parents", lambda d: d.update(nodes=[{"children": [2]}, {"children": [2]}, {"name": "c"}],
                                            scenes=[{"nodes": [0, 1]}])),
    ("node-child-missing", setp(["nodes", 0, "children"], [5])),
    ("node-deep-300", deep_nodes(300)),
    ("node-matrix-and-trs", setp(["nodes", 0], {"matrix": [1] * 16, "translation": [0, 0, 0]})),
    ("node-matrix-short", setp(["nodes", 0, "matrix"], [1, 0, 0])),
    ("node-rotation-nan-string", setp(["nodes", 0, "rotation"], ["NaN", 0, 0, 1])),
    ("channel-node-missing", setp(["animations", 0, "channels", 0, "target", "node"], 3)),
    ("channel-sampler-missing", setp(["animations", 0, "channels", 0, "sampler"], 4)),
    ("channel-bad-path", setp(["animations", 0, "channels", 0, "target", "path"], "color")),
    ("channel-no-node", delp(["animations", 0, "channels", 0, "target", "node"])),
    ("sampler-input-missing", setp(["animations", 0, "samplers", 0, "input"], 12)),
    ("sampler-output-missing", setp(["animations", 0, "samplers", 0, "output"], 12)),
    ("sampler-bad-interpolation", setp(["animations", 0, "samplers", 0, "interpolation"], "BEZIER")),
    ("cubicspline-short-output", setp(["animations", 0, "samplers", 0, "interpolation"], "CUBICSPLINE")),
    ("no-animations", delp(["animations"])),
    ("empty-animations", setp(["animations"], [])),
    ("animation-no-channels", setp(["animations", 0, "channels"], [])),
    ("asset-version-1", setp(["asset", "version"], "1.0")),
    ("asset-missing", delp(["asset"])),
    ("scene-missing", setp(["scene"], 4)),
    ("mesh-position-missing", lambda d: d.update(meshes=[{"primitives": [{"attributes": {"POSITION": 9}}]}])),
    ("skin-joints-missing", lambda d: d.update(skins=[{"joints": [7]}])),
    ("skin-ibm-missing", lambda d: d.update(skins=[{"joints": [0], "inverseBindMatrices": 9}])),
    ("extensions-required", setp(["extensionsRequired"], ["KHR_draco_mesh_compression"])),
    ("buffers-object", setp(["buffers"], {"0": 1})),
]
for name, edit in GLTF_EDITS:
    bad("gltf", name + ".gltf", gltf(edit))

for name, data in [
    ("empty", b""),
    ("not-json", b"glTF? no"),
    ("json-array", b"[]"),
    ("truncated", gltf()[:300].encode()),
    ("invalid-utf8", gltf().encode()[:40] + b"\xff\xfe" + gltf().encode()[40:]),
    ("nested-10000", b'{"asset":' + b"[" * 10000 + b"]" * 10000 + b"}"),
]:
    bad("gltf", name + ".gltf", data)


def glb(json_bytes, bin_bytes=None, version=2, length=None, json_type=b"JSON"):
    j = json_bytes + b" " * (-len(json_bytes) % 4)
    out = b"glTF" + struct.pack("<II", version, 0) + struct.pack("<I", len(j)) + json_type + j
    if bin_bytes is not None:
        b = bin_bytes + b"\0" * (-len(bin_bytes) % 4)
        out += struct.pack("<I", len(b)) + b"BIN\0" + b
    total = len(out) if length is None else length
    return out[:8] + struct.pack("<I", total & 0xFFFFFFFF) + out[12:]


def glb_doc(edit=None):
    """mini() with buffer 0 in the BIN chunk."""
    d = mini()
    del d["buffers"][0]["uri"]
    if edit:
        edit(d)
    return dumps(d).encode()


BIN = floats([0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0])
GOOD_GLB = glb(glb_doc(), BIN)
for n in range(12):
    bad("glb", f"length-{n}.glb", GOOD_GLB[:n])
for name, data in [
    ("magic-wrong", b"glTf" + GOOD_GLB[4:]),
    ("version-1", glb(glb_doc(), BIN, version=1)),
    ("version-u32-max", glb(glb_doc(), BIN, version=0xFFFFFFFF)),
    ("header-length-zero", glb(glb_doc(), BIN, length=0)),
    ("header-length-11", glb(glb_doc(), BIN, length=11)),
    ("header-length-u32-max", glb(glb_doc(), BIN, length=0xFFFFFFFF)),
    ("header-length-past-end", glb(glb_doc(), BIN, length=len(GOOD_GLB) + 4)),
    ("header-only", GOOD_GLB[:12][:8] + struct.pack("<I", 12)),
    ("json-chunk-length-overflow", GOOD_GLB[:12] + struct.pack("<I", 0xFFFFFFFF) + GOOD_GLB[16:]),
    ("json-chunk-length-past-end", GOOD_GLB[:12] + struct.pack("<I", len(GOOD_GLB)) + GOOD_GLB[16:]),
    ("json-chunk-header-cut", GOOD_GLB[:8] + struct.pack("<I", 16) + GOOD_GLB[12:16]),
    ("bin-chunk-length-overflow", (lambda j: glb(j, BIN)[:20 + len(j) + (-len(j) % 4)] + struct.pack("<I", 0xFFFFFFF0)
                                   + glb(j, BIN)[24 + len(j) + (-len(j) % 4):])(glb_doc())),
    ("first-chunk-bin", glb(glb_doc(), BIN, json_type=b"BIN\0")),
    ("json-chunk-empty", glb(b"", BIN)),
    ("json-chunk-not-json", glb(b"\x00\x01\x02\x03", BIN)),
    ("no-bin-chunk", glb(glb_doc())),
    ("bin-too-short", glb(glb_doc(), BIN[:16])),
    ("bin-nan-values", glb(glb_doc(), floats([0.0, 1.0, float("nan"), 0.0, 0.0, 1.0, 2.0, 3.0]))),
    ("bin-inf-times", glb(glb_doc(), floats([0.0, float("inf"), 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]))),
    ("bytelength-u64-max", glb(glb_doc(setp(["buffers", 0, "byteLength"], 18446744073709551615)), BIN)),
    ("accessor-count-huge", glb(glb_doc(setp(["accessors", 1, "count"], 4000000000)), BIN)),
    ("node-cycle", glb(glb_doc(setp(["nodes", 0, "children"], [0])), BIN)),
    ("uri-percent-ff", glb(glb_doc(setp(["buffers", 0, "uri"], "%FF")), BIN)),
    ("second-buffer-no-uri", glb(glb_doc(lambda d: d["buffers"].append({"byteLength": 4})), BIN)),
]:
    bad("glb", name + ".glb", data)

# ---------------------------------------------------------------- BVH

BVH = ("HIERARCHY\nROOT hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation"
       " Yrotation\n  JOINT spine\n  {\n    OFFSET 0 1 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n"
       "    {\n      OFFSET 0 1 0\n    }\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n0 0 0 0 0 0 0 0 0\n"
       "1 2 3 10 20 30 40 50 60\n")


def bvh(old, new):
    assert old in BVH, old
    return BVH.replace(old, new, 1)


def deep_bvh(depth, frames=1):
    s = "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
    for i in range(1, depth):
        s += f"JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
    s += "}\n" * depth
    s += f"MOTION\nFrames: {frames}\nFrame Time: 0.1\n" + ("0 0 0 " * depth + "\n") * frames
    return s


BVH_CASES = [
    ("empty", ""),
    ("hierarchy-only", "HIERARCHY\n"),
    ("no-motion", BVH.split("MOTION")[0]),
    ("motion-only", "MOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n"),
    ("nan-token", bvh("1 2 3 10", "NaN 2 3 10")),
    ("nan-lower", bvh("1 2 3 10", "nan 2 3 10")),
    ("inf-token", bvh("1 2 3 10", "inf 2 3 10")),
    ("minus-infinity-token", bvh("1 2 3 10", "-infinity 2 3 10")),
    ("overflow-1e400", bvh("1 2 3 10", "1e400 2 3 10")),
    ("overflow-f32", bvh("1 2 3 10", "3.5e38 2 3 10")),
    ("rotation-1e30", bvh("1 2 3 10", "1 2 3 1e30")),
    ("offset-nan", bvh("OFFSET 0 1 0\n    CHANNELS", "OFFSET 0 NaN 0\n    CHANNELS")),
    ("offset-inf", bvh("OFFSET 0 0 0", "OFFSET inf 0 0")),
    ("offset-two-values", bvh("OFFSET 0 0 0", "OFFSET 0 0")),
    ("frame-time-zero", bvh("Frame Time: 0.5", "Frame Time: 0")),
    ("frame-time-negative", bvh("Frame Time: 0.5", "Frame Time: -0.5")),
    ("frame-time-nan", bvh("Frame Time: 0.5", "Frame Time: NaN")),
    ("frame-time-inf", bvh("Frame Time: 0.5", "Frame Time: inf")),
    ("frame-time-tiny", bvh("Frame Time: 0.5", "Frame Time: 1e-45")),
    ("frame-time-huge", bvh("Frame Time: 0.5", "Frame Time: 1e38")),
    ("frame-time-missing", bvh("Frame Time: 0.5\n", "")),
    ("frame-time-text", bvh("Frame Time: 0.5", "Frame Time: fast")),
    ("frames-4000000000", bvh("Frames: 2", "Frames: 4000000000")),
    ("frames-u64-max", bvh("Frames: 2", "Frames: 18446744073709551615")),
    ("frames-over-u64", bvh("Frames: 2", "Frames: 99999999999999999999999")),
    ("frames-negative", bvh("Frames: 2", "Frames: -2")),
    ("frames-zero", bvh("Frames: 2", "Frames: 0")),
    ("frames-more-than-given", bvh("Frames: 2", "Frames: 3")),
    ("frames-fewer-than-given", bvh("Frames: 2", "Frames: 1")),
    ("frames-text", bvh("Frames: 2", "Frames: two")),
    ("frames-missing", bvh("Frames: 2\n", "")),
    ("channels-count-too-high", bvh("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation")),
    ("channels-count-too-low", bvh("CHANNELS 3 Zrotation", "CHANNELS 2 Zrotation")),
    ("channels-count-huge", bvh("CHANNELS 3 Zrotation", "CHANNELS 4000000000 Zrotation")),
    ("channels-count-negative", bvh("CHANNELS 3 Zrotation", "CHANNELS -3 Zrotation")),
    ("channels-unknown-name", bvh("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation")),
    ("channels-duplicate", bvh("CHANNELS 3 Zrotation Xrotation", "CHANNELS 3 Zrotation Zrotation")),
    ("frame-row-short", bvh("1 2 3 10 20 30 40 50 60", "1 2 3 10 20 30 40 50")),
    ("frame-row-long", bvh("1 2 3 10 20 30 40 50 60", "1 2 3 10 20 30 40 50 60 70")),
    ("frame-value-text", bvh("1 2 3 10", "1 two 3 10")),
    ("frame-value-hex", bvh("1 2 3 10", "0x1 2 3 10")),
    ("missing-brace", bvh("    }\n  }\n}", "    }\n  }")),
    ("extra-brace", bvh("}\nMOTION", "}\n}\nMOTION")),
    ("root-no-name", bvh("ROOT hips", "ROOT")),
    ("two-roots", BVH.replace("MOTION", "ROOT b\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n}\nMOTION")),
    ("joint-outside-root", bvh("ROOT hips", "JOINT hips")),
    ("end-site-with-channels", bvh("      OFFSET 0 1 0\n    }", "      OFFSET 0 1 0\n      CHANNELS 1 Xrotation\n    }")),
    ("unknown-keyword", bvh("  JOINT spine", "  BONE spine")),
    ("deep-300", deep_bvh(300)),
    ("deep-1000-no-motion", deep_bvh(1000).split("MOTION")[0]),
    ("joints-over-limit", deep_bvh(70)),
    ("frames-over-limit", deep_bvh(1, 1001)),
    ("binary-garbage", bytes(range(256)) * 4),
    ("nul-bytes", BVH.replace("hips", "hi\x00ps")),
    ("invalid-utf8-name", BVH.encode().replace(b"hips", b"h\xffps")),
    ("crlf-truncated", BVH.replace("\n", "\r\n")[: len(BVH) // 2]),
    ("truncated-motion", BVH[: BVH.index("1 2 3")] + "1 2"),
]
for name, data in BVH_CASES:
    bad("bvh", name + ".bvh", data)

# Sniffing: uploads with no format parameter.
for name, data in [
    ("empty", b""),
    ("text", b"hello world"),
    ("png-header", b"\x89PNG\r\n\x1a\n" + b"\0" * 32),
    ("glb-magic-only", b"glTF"),
    ("hierarchy-lowercase-garbage", b"hierarchy {{{{"),
    ("bom-then-brace", b"\xef\xbb\xbf{"),
    ("zip-header", b"PK\x03\x04" + b"\0" * 30),
    ("fbx-header", b"Kaydara FBX Binary  \x00\x1a\x00"),
]:
    bad("sniff", name + ".bin", data)

# ---------------------------------------------------------------- HTTP framing


def http(method, path, headers=(), body=b"", content_length=True):
    if isinstance(body, str):
        body = body.encode()
    lines = [f"{method} {path} HTTP/1.1", "Host: 127.0.0.1", "Connection: close"]
    lines += list(headers)
    if content_length and (body or method in ("POST", "PUT")):
        lines.append(f"Content-Length: {len(body)}")
    return "\r\n".join(lines).encode() + b"\r\n\r\n" + body


WAVE_DOC = dumps(WAVE)
GLTF_DOC = gltf()
B = "XyZbOuNdArY"


def multipart(parts, close=True):
    out = b""
    for headers, body in parts:
        out += f"--{B}\r\n".encode() + "".join(h + "\r\n" for h in headers).encode() + b"\r\n"
        out += (body.encode() if isinstance(body, str) else body) + b"\r\n"
    if close:
        out += f"--{B}--\r\n".encode()
    return out


def shared_part(size):
    """Times [0, 1], translations [0,0,0] and [1,2,3], then zeros up to `size` bytes."""
    return floats([0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0]).ljust(size, b"\0")


def shared_part_gltf(nodes, size):
    """`nodes` animated nodes whose 2 * `nodes` buffers all name anim.bin, whole."""
    return dumps({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(nodes))}],
        "nodes": [{"name": f"n{i}"} for i in range(nodes)],
        "buffers": [{"uri": "anim.bin", "byteLength": size} for _ in range(2 * nodes)],
        "bufferViews": [v for i in range(nodes) for v in (
            {"buffer": 2 * i, "byteOffset": 0, "byteLength": 8},
            {"buffer": 2 * i + 1, "byteOffset": 8, "byteLength": 24})],
        "accessors": [a for i in range(nodes) for a in (
            {"bufferView": 2 * i, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]},
            {"bufferView": 2 * i + 1, "componentType": 5126, "count": 2, "type": "VEC3"})],
        "animations": [{
            "name": "shared",
            "channels": [{"sampler": i, "target": {"node": i, "path": "translation"}} for i in range(nodes)],
            "samplers": [{"input": 2 * i, "output": 2 * i + 1, "interpolation": "LINEAR"} for i in range(nodes)],
        }],
    })


MP = f"Content-Type: multipart/form-data; boundary={B}"
FILE_PART = ['Content-Disposition: form-data; name="file"; filename="mini.gltf"', "Content-Type: model/gltf+json"]
HTTP_CASES = [
    ("clip-no-content-type", http("POST", "/v1/clips", [], WAVE_DOC)),
    ("clip-text-plain", http("POST", "/v1/clips", ["Content-Type: text/plain"], WAVE_DOC)),
    ("clip-form-urlencoded", http("POST", "/v1/clips", ["Content-Type: application/x-www-form-urlencoded"], "a=b")),
    ("clip-multipart", http("POST", "/v1/clips", [MP], multipart([(FILE_PART, WAVE_DOC)]))),
    ("clip-content-type-garbage", http("POST", "/v1/clips", ["Content-Type: ;;;==="], WAVE_DOC)),
    ("clip-content-type-json-utf16", http("POST", "/v1/clips", ["Content-Type: application/json; charset=utf-16"],
                                          WAVE_DOC.encode("utf-16-le"))),
    ("clip-empty-body", http("POST", "/v1/clips", ["Content-Type: application/json"], "")),
    ("clip-over-body-limit", http("POST", "/v1/clips", ["Content-Type: application/json"],
                                  '{"name":"' + "x" * (300 * 1024) + '"}')),
    ("clip-gzip-encoding", http("POST", "/v1/clips", ["Content-Type: application/json",
                                                       "Content-Encoding: gzip"], b"\x1f\x8b\x08\x00garbage")),
    ("clip-chunked-bad-json", b"POST /v1/clips HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n"
     b"Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n3\r\n{\"n\r\n0\r\n\r\n"),
    ("put-no-if-match-bad-doc", http("PUT", f"/v1/clips/{CLIP_ID}", ["Content-Type: application/json"], "{}")),
    ("put-if-match-garbage", http("PUT", f"/v1/clips/{CLIP_ID}", ["Content-Type: application/json",
                                                                  "If-Match: not-an-etag"], WAVE_DOC)),
    ("put-if-match-stale", http("PUT", f"/v1/clips/{CLIP_ID}", ["Content-Type: application/json",
                                                                'If-Match: "999"'], WAVE_DOC)),
    ("put-unknown-id", http("PUT", f"/v1/clips/{MISSING_ID}", ["Content-Type: application/json"], WAVE_DOC)),
    ("put-bad-id", http("PUT", "/v1/clips/..%2F..%2Fetc", ["Content-Type: application/json"], WAVE_DOC)),
    ("get-bad-id", http("GET", "/v1/clips/%FF%FE")),
    ("get-id-too-long", http("GET", "/v1/clips/" + "a" * 2000)),
    ("delete-unknown-id", http("DELETE", f"/v1/clips/{MISSING_ID}")),
    ("pose-no-t", http("GET", f"/v1/clips/{CLIP_ID}/pose")),
    ("pose-t-text", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=abc")),
    ("pose-t-nan", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=NaN")),
    ("pose-t-inf", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=inf")),
    ("pose-t-1e400", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=1e400")),
    ("pose-t-twice", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=1&t=2")),
    ("pose-bad-space", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=1&space=world")),
    ("pose-bad-playback", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=1&playback=reverse")),
    ("pose-bad-ease", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=1&ease=bounce")),
    ("pose-bad-format", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=1&format=xml")),
    ("pose-unknown-param", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=1&frobnicate=1")),
    ("pose-query-bad-percent", http("GET", f"/v1/clips/{CLIP_ID}/pose?t=%FF")),
    ("pose-unknown-clip", http("GET", f"/v1/clips/{MISSING_ID}/pose?t=1")),
    ("sample-empty", http("POST", f"/v1/clips/{CLIP_ID}/sample", ["Content-Type: application/json"], "{}")),
    ("sample-times-nan", http("POST", f"/v1/clips/{CLIP_ID}/sample", ["Content-Type: application/json"],
                              '{"times":["NaN"]}')),
    ("sample-too-many-times", http("POST", f"/v1/clips/{CLIP_ID}/sample", ["Content-Type: application/json"],
                                   dumps({"times": list(range(10001))}))),
    ("sample-not-json", http("POST", f"/v1/clips/{CLIP_ID}/sample", ["Content-Type: application/json"], "[[[")),
    ("sample-text-plain", http("POST", f"/v1/clips/{CLIP_ID}/sample", ["Content-Type: text/plain"], "{}")),
    ("list-limit-zero", http("GET", "/v1/clips?limit=0")),
    ("list-limit-huge", http("GET", "/v1/clips?limit=99999999999999999999")),
    ("list-cursor-garbage", http("GET", "/v1/clips?cursor=%00%01")),
    ("list-unknown-param", http("GET", "/v1/clips?sort=name")),
    ("unknown-route", http("GET", "/v1/animations")),
    # PATCH changes name, tags, metadata, playback and events only: a patch of the tracks is refused.
    ("patch-tracks", http("PATCH", f"/v1/clips/{CLIP_ID}", ["Content-Type: application/merge-patch+json"],
                          '{"tracks":[]}')),
    ("method-delete-collection", http("DELETE", "/v1/clips")),
    ("stream-not-websocket", http("GET", f"/v1/clips/{CLIP_ID}/stream")),
    ("stream-bad-fps", http("GET", f"/v1/clips/{CLIP_ID}/stream?fps=0", [
        "Upgrade: websocket", "Connection: Upgrade", "Sec-WebSocket-Version: 13",
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ=="])),
    ("import-bad-format-param", http("POST", "/v1/clips/import?format=fbx", ["Content-Type: model/gltf+json"],
                                     GLTF_DOC)),
    ("import-bad-interpolation", http("POST", "/v1/clips/import?format=bvh&interpolation=cubic_hermite",
                                      ["Content-Type: application/octet-stream"], BVH)),
    ("import-empty-body", http("POST", "/v1/clips/import", ["Content-Type: application/octet-stream"], "")),
    ("import-multipart-truncated", http("POST", "/v1/clips/import", [MP],
                                        multipart([(FILE_PART, GLTF_DOC)], close=False))),
    ("import-multipart-cut-mid-part", http("POST", "/v1/clips/import", [MP],
                                           multipart([(FILE_PART, GLTF_DOC)])[:200])),
    ("import-multipart-no-boundary", http("POST", "/v1/clips/import", ["Content-Type: multipart/form-data"],
                                          multipart([(FILE_PART, GLTF_DOC)]))),
    ("import-multipart-wrong-boundary", http("POST", "/v1/clips/import",
                                             ["Content-Type: multipart/form-data; boundary=other"],
                                             multipart([(FILE_PART, GLTF_DOC)]))),
    ("import-multipart-no-document", http("POST", "/v1/clips/import", [MP], multipart([(
        ['Content-Disposition: form-data; name="other"; filename="a.txt"'], "hello")]))),
    ("import-multipart-empty", http("POST", "/v1/clips/import", [MP], f"--{B}--\r\n")),
    ("import-multipart-headers-garbage", http("POST", "/v1/clips/import", [MP],
                                              f"--{B}\r\n\x01\x02\x03\r\n\r\nx\r\n--{B}--\r\n")),
    ("import-multipart-external-uri", http("POST", "/v1/clips/import", [MP], multipart([
        (FILE_PART, gltf(setp(["buffers", 0, "uri"], "../secret.bin"))),
        (['Content-Disposition: form-data; name="bin"; filename="../secret.bin"'], "AAAA")]))),
    ("import-multipart-missing-sibling", http("POST", "/v1/clips/import", [MP], multipart([
        (FILE_PART, gltf(setp(["buffers", 0, "uri"], "anim.bin")))]))),
    ("import-multipart-sibling-short", http("POST", "/v1/clips/import", [MP], multipart([
        (FILE_PART, gltf(setp(["buffers", 0, "uri"], "anim.bin"))),
        (['Content-Disposition: form-data; name="bin"; filename="anim.bin"'], b"\0\0\0\0")]))),
    # 64 buffers all naming one 64 KiB part: 4 MiB of buffers read, over the replay's 1 MiB (413).
    ("import-multipart-shared-part-over-limit", http("POST", "/v1/clips/import", [MP], multipart([
        (FILE_PART, shared_part_gltf(32, 64 * 1024)),
        (['Content-Disposition: form-data; name="bin"; filename="anim.bin"'], shared_part(64 * 1024))]))),
]
for name, data in HTTP_CASES:
    bad("http", name + ".http", data)
# A frame range of 1e20 frames: counted without wrapping, so too many poses (issue 15).
bad("http", "sample-range-1e20-frames.http", http("POST", f"/v1/clips/{CLIP_ID}/sample",
    ["Content-Type: application/json"], '{"start":0,"end":1e20,"fps":1}'), "422")


# Graph documents (docs/graphs.md) refused at upload, each with its status.
def graph(nodes, parameters=None, **top):
    doc = {"name": "corpus-graph", "parameters": parameters or {}, "nodes": nodes}
    doc.update(top or {"output": next(iter(nodes))})
    return dumps(doc)


XY = {"x": {"type": "float", "default": 0, "min": 0, "max": 1}, "y": {"type": "float", "default": 0, "min": 0, "max": 1}}
GRAPH_CASES = [
    ("graph-not-json", "{\"name\": \"g\", \"nodes\"", "400"),
    ("graph-unknown-field", dumps({"name": "g", "nodes": {}, "output": "a", "bogus": 1}), "422"),
    ("graph-collinear-blend2d", graph({"b": {"blend2d": {"x": "x", "y": "y", "points": [
        {"clip": CLIP_ID, "at": [0, 0]}, {"clip": CLIP_ID, "at": [0.5, 0.5]}, {"clip": CLIP_ID, "at": [1, 1]}]}}},
        XY), "422"),
    ("graph-node-cycle", graph({"a": {"layers": [{"node": "b"}]}, "b": {"layers": [{"node": "a"}]}}), "422"),
    ("graph-unknown-parameter", graph({"b": {"blend1d": {"parameter": "speed", "points": [
        {"clip": CLIP_ID, "at": 0}]}}}), "422"),
    ("graph-missing-clip", graph({"a": {"clip": MISSING_ID}}), "404"),
    ("graph-too-many-points", graph({"b": {"blend2d": {"x": "x", "y": "y", "points": [
        {"clip": CLIP_ID, "at": [i / 40, (i * 7 % 40) / 40]} for i in range(40)]}}}, XY), "422"),
]
for name, body, status in GRAPH_CASES:
    bad("http", name + ".http", http("POST", "/v1/graphs", ["Content-Type: application/json"], body), status)
bad("http", "graph-put-unknown-id.http", http("PUT", f"/v1/graphs/{MISSING_ID}", ["Content-Type: application/json"],
    graph({"a": {"clip": CLIP_ID}})), "404")

# ---------------------------------------------------------------- gRPC framing


def varint(n):
    out = b""
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out += bytes([b | 0x80])
        else:
            return out + bytes([b])


def field(num, wire, payload):
    key = varint(num << 3 | wire)
    if wire == 0:
        return key + varint(payload)
    if wire == 1:
        return key + struct.pack("<d", payload)
    if wire == 2:
        payload = payload.encode() if isinstance(payload, str) else payload
        return key + varint(len(payload)) + payload
    if wire == 5:
        return key + struct.pack("<f", payload)
    raise ValueError(wire)


def packed_floats(num, values):
    return field(num, 2, struct.pack(f"<{len(values)}f", *values))


def packed_doubles(num, values):
    return field(num, 2, struct.pack(f"<{len(values)}d", *values))


def pb_track(joint="root", channel=1, interp=2, times=(0.0, 1.0), values=(0, 0, 0, 1, 1, 1), extra=b""):
    return (field(1, 2, joint) + field(2, 0, channel) + field(3, 0, interp) + packed_floats(4, list(times))
            + packed_floats(5, list(values)) + extra)


def pb_clip(name="g", tracks=None, extra=b""):
    tracks = [pb_track()] if tracks is None else tracks
    return field(1, 2, name) + b"".join(field(3, 2, t) for t in tracks) + extra


def put(clip=None, clip_id="", extra=b""):
    return (field(1, 2, clip_id) if clip_id else b"") + (field(2, 2, clip) if clip is not None else b"") + extra


def frame(msg, flag=0, length=None):
    return bytes([flag]) + struct.pack(">I", len(msg) if length is None else length) + msg


GOOD_PUT = put(pb_clip())
NAN, INF = float("nan"), float("inf")
GRPC_CASES = [
    # framing
    ("PutClip", "empty-body", b""),
    ("PutClip", "prefix-cut-3-bytes", frame(GOOD_PUT)[:3]),
    ("PutClip", "prefix-only", frame(GOOD_PUT)[:5]),
    ("PutClip", "length-longer-than-body", frame(GOOD_PUT, length=len(GOOD_PUT) + 100)),
    ("PutClip", "length-u32-max", frame(GOOD_PUT, length=0xFFFFFFFF)),
    ("PutClip", "length-over-4mib", frame(GOOD_PUT, length=5 << 20)),
    ("PutClip", "compressed-flag-no-encoding", frame(GOOD_PUT, flag=1)),
    ("PutClip", "compression-flag-2", frame(GOOD_PUT, flag=2)),
    ("PutClip", "compression-flag-255", frame(GOOD_PUT, flag=255)),
    ("PutClip", "message-cut", frame(GOOD_PUT)[:-4]),
    ("Sample", "empty-body", b""),
    ("Sample", "length-u32-max", frame(b"", length=0xFFFFFFFF)),
    ("Sample", "compressed-flag-no-encoding", frame(field(1, 2, CLIP_ID), flag=1)),
    ("GetClip", "length-over-4mib", frame(b"", length=(4 << 20) + 1)),
    ("DeleteClip", "compression-flag-7", frame(field(1, 2, MISSING_ID), flag=7)),
    ("StreamFrames", "length-u32-max", frame(b"", length=0xFFFFFFFF)),
    ("StreamFrames", "compressed-flag-no-encoding", frame(field(1, 2, CLIP_ID) + field(2, 0, 30), flag=1)),
    ("ListClips", "garbage-prefix", b"\x80\x80\x80\x80\x80\x80"),
    # protobuf encoding
    ("PutClip", "wire-type-7", frame(b"\x0f\x00")),
    ("PutClip", "wire-type-6", frame(b"\x0e\x00")),
    ("PutClip", "field-zero", frame(b"\x00\x00")),
    ("PutClip", "varint-11-bytes", frame(b"\x18" + b"\xff" * 10 + b"\x01")),
    ("PutClip", "varint-cut", frame(b"\x18\xff\xff")),
    ("PutClip", "length-delimited-past-end", frame(b"\x12\xff\xff\xff\x0f" + b"\x00" * 8)),
    ("PutClip", "string-invalid-utf8", frame(field(1, 2, b"\xff\xfe") + field(2, 2, pb_clip()))),
    ("PutClip", "clip-name-invalid-utf8", frame(put(field(1, 2, b"\xc3\x28") + field(3, 2, pb_track())))),
    ("PutClip", "nested-groups", frame(b"\x13" * 200 + b"\x14" * 200)),
    ("PutClip", "nested-messages-deep", frame((lambda m: [m := field(2, 2, m) for _ in range(120)][-1])(b""))),
    ("PutClip", "packed-floats-cut", frame(put(field(1, 2, "g") + field(3, 2, field(4, 2, b"\x00\x00\x80"))))),
    ("Sample", "time-wrong-wire-type", frame(field(1, 2, CLIP_ID) + field(2, 0, 5))),
    # content
    ("PutClip", "no-clip", frame(put())),
    ("PutClip", "no-tracks", frame(put(pb_clip(tracks=[])))),
    ("PutClip", "empty-name", frame(put(pb_clip(name="")))),
    ("PutClip", "name-300", frame(put(pb_clip(name="n" * 300)))),
    ("PutClip", "channel-unspecified", frame(put(pb_clip(tracks=[pb_track(channel=0)])))),
    ("PutClip", "channel-99", frame(put(pb_clip(tracks=[pb_track(channel=99)])))),
    ("PutClip", "interpolation-99", frame(put(pb_clip(tracks=[pb_track(interp=99)])))),
    ("PutClip", "times-nan", frame(put(pb_clip(tracks=[pb_track(times=(0.0, NAN))])))),
    ("PutClip", "times-inf", frame(put(pb_clip(tracks=[pb_track(times=(0.0, INF))])))),
    ("PutClip", "times-decreasing", frame(put(pb_clip(tracks=[pb_track(times=(1.0, 0.0))])))),
    ("PutClip", "values-nan", frame(put(pb_clip(tracks=[pb_track(values=(0, 0, NAN, 1, 1, 1))])))),
    ("PutClip", "values-inf", frame(put(pb_clip(tracks=[pb_track(values=(0, 0, INF, 1, 1, 1))])))),
    ("PutClip", "values-not-multiple-of-3", frame(put(pb_clip(tracks=[pb_track(values=(0, 0, 0, 1, 1))])))),
    ("PutClip", "rotation-zero", frame(put(pb_clip(tracks=[pb_track(channel=2, values=(0, 0, 0, 0, 0, 0, 0, 1))])))),
    ("PutClip", "rotation-three-floats", frame(put(pb_clip(tracks=[pb_track(channel=2, values=(0, 0, 0, 1, 1, 1))])))),
    ("PutClip", "hermite-no-tangents", frame(put(pb_clip(tracks=[pb_track(interp=4)])))),
    ("PutClip", "ends-on-linear", frame(put(pb_clip(tracks=[pb_track(extra=field(8, 0, 3))])))),
    ("PutClip", "ends-99", frame(put(pb_clip(tracks=[pb_track(interp=3, extra=field(8, 0, 99))])))),
    ("PutClip", "tension-nan", frame(put(pb_clip(tracks=[pb_track(interp=3, extra=field(9, 5, NAN))])))),
    ("PutClip", "speed-constant-rotation", frame(put(pb_clip(tracks=[pb_track(
        channel=2, values=(0, 0, 0, 1, 0, 0, 0, 1), extra=field(10, 0, 2))])))),
    ("PutClip", "playback-99", frame(put(pb_clip(extra=field(5, 0, 99))))),
    ("PutClip", "event-time-nan", frame(put(pb_clip(extra=field(4, 2, field(1, 5, NAN) + field(2, 2, "e")))))),
    ("PutClip", "skeleton-parent-unknown", frame(put(pb_clip(extra=field(2, 2, field(1, 2, field(1, 2, "root")
                                                                                         + field(2, 2, "nobody"))))))),
    ("PutClip", "skeleton-duplicate-joint", frame(put(pb_clip(extra=field(2, 2, field(1, 2, field(1, 2, "root")) * 2))))),
    ("PutClip", "inverse-bind-short", frame(put(pb_clip(extra=field(2, 2, field(1, 2, field(1, 2, "root")
                                                                                    + packed_floats(4, [1, 0]))))))),
    ("PutClip", "rest-translation-two", frame(put(pb_clip(extra=field(2, 2, field(1, 2, field(1, 2, "root")
                                                                                     + field(3, 2, packed_floats(1, [0, 1])))))))),
    ("PutClip", "replace-unknown-id", frame(put(pb_clip(), clip_id=MISSING_ID))),
    ("PutClip", "replace-bad-id", frame(put(pb_clip(), clip_id="../../etc"))),
    ("PutClip", "replace-stale-version", frame(put(pb_clip(), clip_id=CLIP_ID, extra=field(3, 0, 999)))),
    ("PutClip", "tracks-over-limit", frame(put(pb_clip(tracks=[pb_track(joint=f"j{i}") for i in range(65)])))),
    ("PutClip", "keys-over-limit", frame(put(pb_clip(tracks=[pb_track(
        times=[float(i) for i in range(1001)], values=[0.0] * 3003)])))),
    ("Sample", "unknown-clip", frame(field(1, 2, MISSING_ID) + field(2, 1, 0.5))),
    ("Sample", "bad-id", frame(field(1, 2, "x") + field(2, 1, 0.5))),
    ("Sample", "time-nan", frame(field(1, 2, CLIP_ID) + field(2, 1, NAN))),
    ("Sample", "time-inf", frame(field(1, 2, CLIP_ID) + field(2, 1, INF))),
    ("Sample", "space-99", frame(field(1, 2, CLIP_ID) + field(3, 0, 99))),
    ("Sample", "playback-99", frame(field(1, 2, CLIP_ID) + field(4, 0, 99))),
    ("Sample", "ease-99", frame(field(1, 2, CLIP_ID) + field(5, 0, 99))),
    ("Sample", "format-99", frame(field(1, 2, CLIP_ID) + field(6, 0, 99))),
    ("Sample", "format-skinning-no-skin", frame(field(1, 2, CLIP_ID) + field(6, 0, 3))),
    ("SampleBatch", "no-when", frame(field(1, 2, CLIP_ID))),
    ("SampleBatch", "times-nan", frame(field(1, 2, CLIP_ID) + field(2, 2, packed_doubles(1, [0.0, NAN])))),
    ("SampleBatch", "too-many-times", frame(field(1, 2, CLIP_ID) + field(2, 2, packed_doubles(1, [0.0] * 10001)))),
    ("SampleBatch", "range-fps-zero", frame(field(1, 2, CLIP_ID) + field(3, 2, field(1, 1, 0.0) + field(2, 1, 1.0)))),
    ("SampleBatch", "range-fps-nan", frame(field(1, 2, CLIP_ID) + field(3, 2, field(2, 1, 1.0) + field(3, 1, NAN)))),
    ("SampleBatch", "range-end-before-start", frame(field(1, 2, CLIP_ID) + field(3, 2, field(1, 1, 5.0)
                                                                                    + field(2, 1, 1.0) + field(3, 1, 30.0)))),
    ("SampleBatch", "range-too-many-frames", frame(field(1, 2, CLIP_ID) + field(3, 2, field(2, 1, 1e9)
                                                                                   + field(3, 1, 240.0)))),
    ("StreamFrames", "fps-zero", frame(field(1, 2, CLIP_ID))),
    ("StreamFrames", "fps-1000", frame(field(1, 2, CLIP_ID) + field(2, 0, 1000))),
    ("StreamFrames", "speed-nan", frame(field(1, 2, CLIP_ID) + field(2, 0, 30) + field(4, 1, NAN))),
    ("StreamFrames", "speed-huge", frame(field(1, 2, CLIP_ID) + field(2, 0, 30) + field(4, 1, 1e9))),
    ("StreamFrames", "start-inf", frame(field(1, 2, CLIP_ID) + field(2, 0, 30) + field(3, 1, INF))),
    ("StreamFrames", "unknown-clip", frame(field(1, 2, MISSING_ID) + field(2, 0, 30))),
    ("GetClip", "unknown-clip", frame(field(1, 2, MISSING_ID))),
    ("GetClip", "bad-id", frame(field(1, 2, "%FF"))),
    ("DeleteClip", "unknown-clip", frame(field(1, 2, MISSING_ID))),
    ("ListClips", "cursor-garbage", frame(field(1, 2, "\x00\x01"))),
    # Issue 15: joint names over 256 characters, and the streaming batch's rules.
    ("PutClip", "joint-name-257-chars", frame(put(pb_clip(tracks=[pb_track(joint="j" * 257)])))),
    ("SampleStream", "no-when", frame(field(1, 2, CLIP_ID))),
    ("SampleStream", "range-too-many-frames", frame(field(1, 2, CLIP_ID) + field(3, 2, field(2, 1, 1e9)
                                                                                    + field(3, 1, 240.0)))),
]
for method, name, data in GRPC_CASES:
    bad("grpc", f"{method}.{name}.bin", data)

# ---------------------------------------------------------------- valid files

for i, (interp, ends) in enumerate([("step", None), ("linear", None), ("catmull_rom", "reflect"),
                                    ("catmull_rom", "zero_slope"), ("b_spline", "reflect")]):
    def edit(d, interp=interp, ends=ends):
        for t in d["tracks"]:
            t["interpolation"] = interp
            t.pop("ends", None)
            if ends:
                t["ends"] = ends
    good("json", f"wave-{i}-{interp}-{ends or 'default'}.json", wave(edit))
for playback in ["once", "loop", "ping_pong"]:
    good("json", f"wave-playback-{playback}.json", wave(setp(["playback"], playback)))
good("json", "no-skeleton.json", wave(lambda d: d.pop("skeleton")))
good("json", "no-events.json", wave(lambda d: d.pop("events")))
good("json", "one-key-step.json", dumps({"name": "one", "tracks": [
    {"joint": "j", "channel": "scale", "interpolation": "step", "times": [0], "values": [[1, 2, 3]]}]}))
good("json", "hermite.json", wave(lambda d: d["tracks"][0].update(
    interpolation="cubic_hermite", in_tangents=[[0, 0, 0]] * 4, out_tangents=[[1, 0, 0]] * 4)))
good("json", "tension.json", wave(setp(["tracks", 0, "tension"], 0.25)))
good("json", "constant-speed.json", wave(setp(["tracks", 0, "speed"], "constant")))
good("json", "unicode-name.json", wave(setp(["name"], "Gruß ✋ 手を振る")))
good("json", "tracks-at-limit.json", many_tracks(64))
good("json", "negative-times.json", wave(setp(["tracks", 0, "times"], [-3, -1, 0.5, 2])))
# Huge but finite components: the direction is well defined, so it is normalised, not refused.
good("json", "quaternion-huge-components.json", wave(setp(["tracks", 1, "values", 1], [3e38, 3e38, 3e38, 3e38])))
good("json", "long-name-256.json", wave(setp(["name"], "n" * 256)))

for interp in ["STEP", "LINEAR"]:
    good("gltf", f"mini-{interp.lower()}.gltf", gltf(setp(["animations", 0, "samplers", 0, "interpolation"], interp)))
good("gltf", "mini-rotation.gltf", gltf(lambda d: (
    d["buffers"].__setitem__(0, {"byteLength": 40, "uri": b64uri(floats([0, 1, 0, 0, 0, 1, 0, 0, 0.7071068, 0.7071068]))}),
    d["bufferViews"].__setitem__(1, {"buffer": 0, "byteOffset": 8, "byteLength": 32}),
    d["accessors"][1].update(type="VEC4"),
    d["animations"][0]["channels"][0]["target"].update(path="rotation"))))
good("gltf", "mini-scale.gltf", gltf(setp(["animations", 0, "channels", 0, "target", "path"], "scale")))
good("gltf", "mini-cubicspline.gltf", gltf(lambda d: (
    d["buffers"].__setitem__(0, {"byteLength": 80, "uri": b64uri(floats([0, 1] + [0, 0, 0] * 6))}),
    d["bufferViews"].__setitem__(1, {"buffer": 0, "byteOffset": 8, "byteLength": 72}),
    d["accessors"][1].update(count=6),
    d["animations"][0]["samplers"][0].update(interpolation="CUBICSPLINE"))))
good("gltf", "mini-deep-20.gltf", gltf(deep_nodes(20)))
good("gltf", "mini-two-animations.gltf", gltf(lambda d: d["animations"].append(
    {"name": "again", "channels": d["animations"][0]["channels"], "samplers": d["animations"][0]["samplers"]})))
good("gltf", "mini-matrix-node.gltf", gltf(lambda d: d["nodes"].append(
    {"name": "m", "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 2, 3, 1]}) or d["scenes"][0]["nodes"].append(1)))
good("gltf", "mini-extras.gltf", gltf(setp(["nodes", 0, "extras"], {"note": "hi"})))
good("gltf", "mini-unicode-node.gltf", gltf(setp(["nodes", 0, "name"], "Knochen ✓")))
good("glb", "mini.glb", GOOD_GLB)
good("glb", "mini-step.glb", glb(glb_doc(setp(["animations", 0, "samplers", 0, "interpolation"], "STEP")), BIN))
good("glb", "mini-unpadded-end.glb", (lambda b: b[:8] + struct.pack("<I", len(b) - 0) + b[12:])(GOOD_GLB))
good("glb", "mini-extra-chunk.glb", (lambda b: b[:8] + struct.pack("<I", len(b) + 12) + b[12:]
                                     + struct.pack("<I", 4) + b"XTRA" + b"abcd")(GOOD_GLB))
good("glb", "mini-deep-10.glb", glb(glb_doc(deep_nodes(10)), BIN))

good("bvh", "two-joints.bvh", BVH)
good("bvh", "crlf.bvh", BVH.replace("\n", "\r\n"))
good("bvh", "tabs.bvh", BVH.replace("  ", "\t"))
good("bvh", "one-frame.bvh", bvh("Frames: 2", "Frames: 1").replace("1 2 3 10 20 30 40 50 60\n", ""))
good("bvh", "deep-30.bvh", deep_bvh(30, 3))
good("bvh", "frames-at-limit.bvh", deep_bvh(1, 1000))
good("bvh", "joints-at-limit.bvh", deep_bvh(64))
good("bvh", "scientific-notation.bvh", bvh("1 2 3 10", "1e0 2.0E+0 3 1e1"))
good("bvh", "xyz-order.bvh", BVH.replace("Zrotation Xrotation Yrotation", "Xrotation Yrotation Zrotation"))
good("bvh", "positions-every-joint.bvh", bvh("CHANNELS 3 Zrotation", "CHANNELS 6 Xposition Yposition Zposition Zrotation")
     .replace("0 0 0 0 0 0 0 0 0\n", "0 0 0 0 0 0 0 0 0 0 0 0\n").replace("40 50 60", "1 1 1 40 50 60"))

# Real files from ../shared/testdata, referenced by path (third-party: never copied here).
SHARED = [
    ("gltf", "gltf/AnimatedTriangle/AnimatedTriangle.gltf"),
    ("gltf", "gltf/BoxAnimated/BoxAnimated.gltf"),
    ("gltf", "gltf/RiggedSimple/RiggedSimple.gltf"),
    ("glb", "gltf/Fox/Fox.glb"),
]  # CesiumMan and the CMU takes exceed the replay server's small limits (413, rightly).


def main():
    with open(os.path.join(HERE, "index.tsv"), "w") as f:
        f.write("# file\texpected (4xx / a status / a gRPC code name; 2xx for valid files). "
                "Written by generate.py; exact statuses recorded with INBETWEEN_CORPUS_RECORD=1.\n")
        for rel, data, expect in files:
            path = os.path.join(HERE, rel)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "wb") as out:
                out.write(data)
            f.write(f"{rel}\t{expect}\n")
        for area, path in SHARED:
            f.write(f"@shared/{path}\t2xx\t{area}\n")


if __name__ == "__main__":
    for sub in ["malformed", "valid"]:
        shutil.rmtree(os.path.join(HERE, sub), ignore_errors=True)
    main()
