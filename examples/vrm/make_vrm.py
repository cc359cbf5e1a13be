#!/usr/bin/env python3
"""Writes tiny_humanoid.vrm: a small VRM 1.0 humanoid (a GLB) to try
characters, retargeting and spring chains on (docs/characters.md,
docs/springs.md). Python 3 standard library only. Run from anywhere:
`python3 make_vrm.py` rewrites the file beside this script, byte for byte
the same.

What it holds:

- 22 joints in a T-pose facing +Z (VRM 1.0's convention: the model's left is
  +X), metres, no rest rotations. Their names (`J00`...) say nothing on
  purpose: the roles come from `VRMC_vrm.humanoid.humanBones`, which names
  hips, spine, chest, neck, head, both upper and lower arms, hands, upper and
  lower legs and feet.
- A skin over them and a mesh of one box per bone, each box bound to the
  bone's parent joint, so the viewer has something to draw.
- `VRMC_springBone`: a three-joint tail (`T0`-`T2`, below the hips) that
  collides with a sphere on the hips, and a two-joint hair strand (`H0`,
  `H1`, on the head).
- One animation, "sway": two seconds of the hips, spine and head rocking
  about Z and the arms rising and falling, the last key equal to the first
  so that it loops.
"""

import json
import math
import os
import struct

# name, parent index (None: a scene root), rest translation relative to the parent
JOINTS = [
    ("J00", None, (0.0, 0.90, 0.0)),  # hips
    ("J01", 0, (0.0, 0.10, 0.0)),  # spine
    ("J02", 1, (0.0, 0.15, 0.0)),  # chest
    ("J03", 2, (0.0, 0.20, 0.0)),  # neck
    ("J04", 3, (0.0, 0.10, 0.0)),  # head
    ("J05", 2, (0.18, 0.15, 0.0)),  # left upper arm
    ("J06", 5, (0.25, 0.0, 0.0)),  # left lower arm
    ("J07", 6, (0.22, 0.0, 0.0)),  # left hand
    ("J08", 2, (-0.18, 0.15, 0.0)),  # right upper arm
    ("J09", 8, (-0.25, 0.0, 0.0)),  # right lower arm
    ("J10", 9, (-0.22, 0.0, 0.0)),  # right hand
    ("J11", 0, (0.09, -0.05, 0.0)),  # left upper leg
    ("J12", 11, (0.0, -0.40, 0.0)),  # left lower leg
    ("J13", 12, (0.0, -0.40, 0.0)),  # left foot
    ("J14", 0, (-0.09, -0.05, 0.0)),  # right upper leg
    ("J15", 14, (0.0, -0.40, 0.0)),  # right lower leg
    ("J16", 15, (0.0, -0.40, 0.0)),  # right foot
    ("T0", 0, (0.0, -0.02, -0.10)),  # tail
    ("T1", 17, (0.0, -0.05, -0.15)),
    ("T2", 18, (0.0, -0.05, -0.15)),
    ("H0", 4, (0.0, 0.12, -0.06)),  # hair strand
    ("H1", 20, (0.0, -0.08, -0.06)),
]

HUMAN_BONES = {
    "hips": 0, "spine": 1, "chest": 2, "neck": 3, "head": 4,
    "leftUpperArm": 5, "leftLowerArm": 6, "leftHand": 7,
    "rightUpperArm": 8, "rightLowerArm": 9, "rightHand": 10,
    "leftUpperLeg": 11, "leftLowerLeg": 12, "leftFoot": 13,
    "rightUpperLeg": 14, "rightLowerLeg": 15, "rightFoot": 16,
}

# The sway's key times, seconds: the last key repeats the first.
TIMES = [0.0, 0.5, 1.0, 1.5, 2.0]
PHASE = [0.0, 1.0, 0.0, -1.0, 0.0]


def about(axis, degrees):
    """[x, y, z, w] of a rotation by `degrees` about the unit `axis`."""
    h = math.radians(degrees) / 2
    return [axis[0] * math.sin(h), axis[1] * math.sin(h), axis[2] * math.sin(h), math.cos(h)]


# joint index -> its rotation keys (degrees about an axis, one per phase)
SWAY = {
    0: ((0, 0, 1), 8.0),  # hips rock
    1: ((0, 0, 1), -5.0),  # the spine leans back against them
    4: ((0, 0, 1), -4.0),  # the head keeps level
    5: ((0, 0, 1), -30.0),  # arms fall and rise a little (a T-pose rocking)
    8: ((0, 0, 1), -30.0),
    6: ((0, 1, 0), 20.0),  # elbows bend forward
    9: ((0, 1, 0), -20.0),
}


def world_positions():
    out = []
    for _, parent, t in JOINTS:
        base = out[parent] if parent is not None else (0.0, 0.0, 0.0)
        out.append(tuple(b + x for b, x in zip(base, t)))
    return out


class Bin:
    """The BIN chunk: views appended 4-byte aligned."""

    def __init__(self):
        self.data = bytearray()
        self.views = []
        self.accessors = []

    def view(self, raw, target=None):
        while len(self.data) % 4:
            self.data.append(0)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        self.data += raw
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, fmt, values, kind, component, width, target=None, bounds=False):
        raw = b"".join(struct.pack("<" + fmt * width, *v) if width > 1 else struct.pack("<" + fmt, v) for v in values)
        acc = {"bufferView": self.view(raw, target), "componentType": component, "count": len(values), "type": kind}
        if bounds:
            acc["min"] = [min(v[i] for v in values) for i in range(width)]
            acc["max"] = [max(v[i] for v in values) for i in range(width)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


FLOAT, UBYTE, USHORT = 5126, 5121, 5123
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def r4(x):
    """Rounded to what a float32 keeps, so the output is stable."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def boxes(world):
    """One box per bone (parent joint to child joint), 0.03 m thick, bound
    to the parent; corner normals."""
    positions, normals, joints, weights, indices = [], [], [], [], []
    faces = [(0, 1, 2), (0, 2, 3), (4, 6, 5), (4, 7, 6), (0, 4, 5), (0, 5, 1),
             (1, 5, 6), (1, 6, 2), (2, 6, 7), (2, 7, 3), (3, 7, 4), (3, 4, 0)]
    for child, (_, parent, _) in enumerate(JOINTS):
        if parent is None:
            continue
        a, b = world[parent], world[child]
        lo = [min(a[i], b[i]) - 0.03 for i in range(3)]
        hi = [max(a[i], b[i]) + 0.03 for i in range(3)]
        centre = [(lo[i] + hi[i]) / 2 for i in range(3)]
        base = len(positions)
        for corner in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]:
            p = [hi[i] if corner[i] else lo[i] for i in range(3)]
            d = [p[i] - centre[i] for i in range(3)]
            n = math.sqrt(sum(x * x for x in d))
            positions.append(tuple(r4(x) for x in p))
            normals.append(tuple(r4(x / n) for x in d))
            joints.append((parent, 0, 0, 0))
            weights.append((1.0, 0.0, 0.0, 0.0))
        indices += [base + i for f in faces for i in f]
    return positions, normals, joints, weights, indices


def build():
    world = world_positions()
    out = Bin()
    positions, normals, joints, weights, indices = boxes(world)
    attributes = {
        "POSITION": out.accessor("f", positions, "VEC3", FLOAT, 3, ARRAY_BUFFER, bounds=True),
        "NORMAL": out.accessor("f", normals, "VEC3", FLOAT, 3, ARRAY_BUFFER),
        "JOINTS_0": out.accessor("B", joints, "VEC4", UBYTE, 4, ARRAY_BUFFER),
        "WEIGHTS_0": out.accessor("f", weights, "VEC4", FLOAT, 4, ARRAY_BUFFER),
    }
    index_accessor = out.accessor("H", indices, "SCALAR", USHORT, 1, ELEMENT_ARRAY_BUFFER)
    # Each joint's inverse bind: the inverse of its world transform (a translation), column-major.
    binds = [(1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -x, -y, -z, 1) for (x, y, z) in world]
    bind_accessor = out.accessor("f", [tuple(r4(v) for v in m) for m in binds], "MAT4", FLOAT, 16)

    times = out.accessor("f", TIMES, "SCALAR", FLOAT, 1, bounds=False)
    out.accessors[times]["min"], out.accessors[times]["max"] = [TIMES[0]], [TIMES[-1]]
    samplers, channels = [], []
    for joint, (axis, degrees) in SWAY.items():
        keys = [tuple(r4(x) for x in about(axis, degrees * p)) for p in PHASE]
        samplers.append({"input": times, "output": out.accessor("f", keys, "VEC4", FLOAT, 4), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": joint, "path": "rotation"}})

    nodes = []
    for i, (name, _, t) in enumerate(JOINTS):
        node = {"name": name, "translation": list(t)}
        children = [c for c, (_, p, _) in enumerate(JOINTS) if p == i]
        if children:
            node["children"] = children
        nodes.append(node)
    body = len(nodes)
    nodes.append({"name": "body", "mesh": 0, "skin": 0})

    doc = {
        "asset": {"version": "2.0", "generator": "inbetween examples/vrm/make_vrm.py"},
        "extensionsUsed": ["VRMC_vrm", "VRMC_springBone"],
        "scene": 0,
        "scenes": [{"name": "tiny_humanoid", "nodes": [0, body]}],
        "nodes": nodes,
        "meshes": [{"name": "body", "primitives": [{"attributes": attributes, "indices": index_accessor}]}],
        "skins": [{"name": "humanoid", "joints": list(range(len(JOINTS))), "inverseBindMatrices": bind_accessor,
                   "skeleton": 0}],
        "animations": [{"name": "sway", "samplers": samplers, "channels": channels}],
        "accessors": out.accessors,
        "bufferViews": out.views,
        "buffers": [{"byteLength": len(out.data)}],
        "extensions": {
            "VRMC_vrm": {
                "specVersion": "1.0",
                "meta": {
                    "name": "tiny_humanoid",
                    "version": "1",
                    "authors": ["the inbetween project"],
                    "copyrightInformation": "Generated by examples/vrm/make_vrm.py",
                    "licenseUrl": "https://spdx.org/licenses/MIT.html",
                    "otherLicenseUrl": "https://spdx.org/licenses/Apache-2.0.html",
                    "avatarPermission": "everyone",
                    "commercialUsage": "corporation",
                    "allowRedistribution": True,
                    "modification": "allowModificationRedistribution",
                    "creditNotation": "unnecessary",
                },
                "humanoid": {"humanBones": {bone: {"node": node} for bone, node in HUMAN_BONES.items()}},
            },
            "VRMC_springBone": {
                "specVersion": "1.0",
                "colliders": [{"node": 0, "shape": {"sphere": {"offset": [0.0, -0.1, 0.0], "radius": 0.12}}}],
                "colliderGroups": [{"name": "hips", "colliders": [0]}],
                "springs": [
                    {"name": "tail", "colliderGroups": [0], "joints": [
                        {"node": 17, "hitRadius": 0.02, "stiffness": 0.8, "gravityPower": 0.2, "dragForce": 0.4},
                        {"node": 18, "hitRadius": 0.02, "stiffness": 0.6, "gravityPower": 0.2, "dragForce": 0.4},
                        {"node": 19},
                    ]},
                    {"name": "hair", "joints": [
                        {"node": 20, "stiffness": 1.0, "gravityPower": 0.1, "dragForce": 0.5},
                        {"node": 21},
                    ]},
                ],
            },
        },
    }
    text = json.dumps(doc, separators=(",", ":"), sort_keys=True).encode()
    text += b" " * (-len(text) % 4)
    data = bytes(out.data) + b"\0" * (-len(out.data) % 4)
    length = 12 + 8 + len(text) + 8 + len(data)
    return (struct.pack("<4sII", b"glTF", 2, length) + struct.pack("<I4s", len(text), b"JSON") + text
            + struct.pack("<I4s", len(data), b"BIN\0") + data)


if __name__ == "__main__":
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "tiny_humanoid.vrm")
    with open(path, "wb") as f:
        f.write(build())
