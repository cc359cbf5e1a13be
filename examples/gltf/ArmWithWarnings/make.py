#!/usr/bin/env python3
"""Writes ArmWithWarnings.gltf: a three-joint arm whose one animation has the
mistakes real exporters make, so importing it shows `inbetween`'s warnings
(docs/warnings.md). Run from anywhere: `python3 make.py` rewrites the file
beside this script, byte for byte the same.

The animation "arm-wave" keys 13 frames, at times 0, 1, ..., 12: frame numbers
written as seconds (`times_look_like_frames`; the clip lasts 12 s where 0.4 s
at 30 fps was meant). Its channels:

0. `root` translation, LINEAR: a small sway along x.
1. `upper` rotation, CUBICSPLINE: a wave of 30 degrees either way about z,
   every other key (with its tangents) written as -q, the way Blender 3.x's
   glTF exporter does (`rotation_hemisphere_flips`): as given, glTF turns the
   long way round between them; `?fix=hemisphere` flips them back.
2. `lower` rotation, LINEAR: a bend of 10 to 40 degrees about x, each key
   written [w, x, y, z] instead of glTF's [x, y, z, w]
   (`rotation_looks_w_first`).
"""

import base64
import json
import math
import os
import struct

FRAMES = 13
times = [float(k) for k in range(FRAMES)]


def phase(k):
    return math.sin(k * math.pi / 6)


def about(axis, degrees):
    """[x, y, z, w] of a rotation by `degrees` about the unit `axis`."""
    h = math.radians(degrees) / 2
    return [axis[0] * math.sin(h), axis[1] * math.sin(h), axis[2] * math.sin(h), math.cos(h)]


# Channel 0: the root sways 0.1 either way along x.
sway = [[0.1 * phase(k), 0.0, 0.0] for k in range(FRAMES)]

# Channel 1: upper arm, 30 degrees either way about z. In-tangent, value,
# out-tangent per key (glTF's CUBICSPLINE layout); the tangents are dq/dt of
# the unit quaternion (per second: the key interval is 1), and every odd key
# is negated together with its tangents.
wave = []
for k in range(FRAMES):
    theta = math.radians(30 * phase(k))
    dtheta = math.radians(30) * math.cos(k * math.pi / 6) * math.pi / 6
    q = about([0, 0, 1], math.degrees(theta))
    dq = [0.0, 0.0, 0.5 * math.cos(theta / 2) * dtheta, -0.5 * math.sin(theta / 2) * dtheta]
    sign = -1.0 if k % 2 else 1.0
    wave += [[sign * c for c in dq], [sign * c for c in q], [sign * c for c in dq]]

# Channel 2: forearm, 10 to 40 degrees about x, written [w, x, y, z].
bend = []
for k in range(FRAMES):
    x, y, z, w = about([1, 0, 0], 25 + 15 * phase(k))
    bend.append([w, x, y, z])

data = bytearray()
views, accessors = [], []


def accessor(kind, rows, bounds=False):
    floats = [c for row in rows for c in row]
    views.append({"buffer": 0, "byteOffset": len(data), "byteLength": 4 * len(floats)})
    data.extend(struct.pack("<%df" % len(floats), *floats))
    a = {"bufferView": len(views) - 1, "componentType": 5126, "count": len(rows), "type": kind}
    if bounds:
        # glTF requires min and max on animation inputs, as stored (f32).
        stored = [struct.unpack("<f", struct.pack("<f", r[0]))[0] for r in rows]
        a["min"], a["max"] = [min(stored)], [max(stored)]
    accessors.append(a)
    return len(accessors) - 1


t = accessor("SCALAR", [[x] for x in times], bounds=True)
samplers = [
    {"input": t, "output": accessor("VEC3", sway), "interpolation": "LINEAR"},
    {"input": t, "output": accessor("VEC4", wave), "interpolation": "CUBICSPLINE"},
    {"input": t, "output": accessor("VEC4", bend), "interpolation": "LINEAR"},
]
gltf = {
    "asset": {"version": "2.0", "generator": "examples/gltf/ArmWithWarnings/make.py"},
    "scene": 0,
    "scenes": [{"nodes": [0]}],
    "nodes": [
        {"name": "root", "children": [1]},
        {"name": "upper", "translation": [0, 1, 0], "children": [2]},
        {"name": "lower", "translation": [0, 1, 0]},
    ],
    "animations": [{
        "name": "arm-wave",
        "channels": [
            {"sampler": 0, "target": {"node": 0, "path": "translation"}},
            {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
            {"sampler": 2, "target": {"node": 2, "path": "rotation"}},
        ],
        "samplers": samplers,
    }],
    "buffers": [{
        "byteLength": len(data),
        "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode(),
    }],
    "bufferViews": views,
    "accessors": accessors,
}

out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "ArmWithWarnings.gltf")
with open(out, "w") as f:
    json.dump(gltf, f, indent=1)
    f.write("\n")
