"""Compact frames (docs/compact-frames.md): a decoder for the binary frames of
``encoding=compact`` streams, poses out as numpy float32 arrays.

    from compact import CompactDecoder
    decoder = CompactDecoder(opened["layout"])
    frame = decoder.decode(message_bytes)   # frame.rotations: (joints, 4)

A decoder keeps the last key frame's values: feed it one stream's frames in order.
A new layout mid-stream (a WebSocket text message ``{"layout", "seq"}``, a later
``compact_layout`` on gRPC) goes to ``decoder.relayout(layout)`` before the frame
after it, a key frame.
"""

import math
import struct
from dataclasses import dataclass

import numpy as np

KEY_FRAME = 1
EVENTS = 2  # an events section follows the body
ROOT_MOTION = 4  # a root motion section follows the body (and the events)
GRAPH = 8  # a graph report section follows (after the root motion)
KNOWN_FLAGS = KEY_FRAME | EVENTS | ROOT_MOTION | GRAPH


class CompactError(ValueError):
    """Bytes that are not a compact frame of the layout; ``code`` is stable."""

    def __init__(self, code, message):
        super().__init__(message)
        self.code = code


@dataclass
class Frame:
    seq: int
    dropped: int
    sent_at_unix_nanos: int
    clip_time: float
    key: bool
    key_seq: int
    translations: np.ndarray  # (joints, 3) float32
    rotations: np.ndarray  # (joints, 4) float32, [x, y, z, w]
    scales: np.ndarray  # (joints, 3) float32
    # The events crossed since the previous frame, in order: indices into the
    # layout's ``events`` (``CompactDecoder.events`` holds their times and names).
    events: list
    # ``{"delta": [x, y, z, yaw], "total": [...]}`` (f32 values), or None.
    root_motion: dict | None
    # A graph stream's report by index into the layout's ``graph``:
    # ``{"state": i, "transition": {"from", "to", "alpha"} or None,
    # "weights": [{"node": i, "weights": [...]}]}`` (f32 values), or None.
    graph: dict | None = None


def _value(field, u):
    """``min + (u * (max - min)) / n`` in doubles; ``min`` when constant."""
    bits, lo, hi = field
    if bits == 0:
        return lo
    return lo + (u * (hi - lo)) / ((1 << bits) - 1)


class _Bits:
    """Bit fields packed least significant bit first."""

    def __init__(self, data, start):
        self.data = data
        self.bit = start * 8

    def read(self, bits):
        if bits == 0:
            return 0
        if self.bit + bits > len(self.data) * 8:
            raise CompactError("compact_truncated", "the frame ends before its joint values")
        first, last = self.bit >> 3, (self.bit + bits - 1) >> 3
        word = int.from_bytes(self.data[first : last + 1], "little") >> (self.bit & 7)
        self.bit += bits
        return word & ((1 << bits) - 1)


def _varint(data, at, what):
    value, shift = 0, 0
    while shift < 64:
        if at[0] >= len(data):
            raise CompactError("compact_truncated", f"the frame ends before its {what}")
        byte = data[at[0]]
        at[0] += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value
        shift += 7
    raise CompactError("compact_varint_overflow", "a varint is longer than 64 bits")


def _read_root_motion(data, at):
    """The root motion section: delta then total, each x, y, z, yaw as little-endian f32s."""
    if at[0] + 32 > len(data):
        raise CompactError("compact_truncated", "the frame ends before its root motion")
    values = list(struct.unpack_from("<8f", data, at[0]))
    at[0] += 32
    return {"delta": values[:4], "total": values[4:]}


def _f32s(data, at, count):
    """``count`` little-endian f32s of the graph report section."""
    if at[0] + 4 * count > len(data):
        raise CompactError("compact_truncated", "the frame ends before its graph report")
    values = list(struct.unpack_from(f"<{count}f", data, at[0]))
    at[0] += 4 * count
    return values


class CompactDecoder:
    """Decodes one stream's compact frames against its ``opened`` layout."""

    def __init__(self, layout):
        self.relayout(layout)

    def relayout(self, layout):
        """Decodes frames of ``layout`` from now on (docs/compact-frames.md, "A new
        layout"): the last key frame is forgotten, so a delta frame before the new
        layout's first key frame is refused."""
        if layout.get("version") != 1:
            raise CompactError("compact_version", f"layout version {layout.get('version')}")
        self.layout = layout
        self.names = [j["name"] for j in layout["joints"]]
        self.joints = [self._compile(j) for j in layout["joints"]]
        self.events = layout.get("events", [])
        self.graph = layout.get("graph") or {"states": [], "nodes": []}
        self.key = None
        self.key_seq = None

    @staticmethod
    def _compile(joint):
        axes = lambda a: [(a["bits"][k], a["min"][k], a["max"][k]) for k in range(3)]
        out = {"translation": axes(joint["translation"]), "scale": axes(joint["scale"])}
        rotation = joint["rotation"]
        if "constant" in rotation:
            out["constant"] = rotation["constant"]
        else:
            s = rotation["smallest_three"]
            out["largest"] = s["largest"]
            out["components"] = [(s["bits"][k], s["min"][k], s["max"][k]) for k in range(4)]
        out["animated"] = "constant" not in out or any(f[0] > 0 for f in out["translation"] + out["scale"])
        return out

    def decode(self, data):
        data = bytes(data)
        if not data:
            raise CompactError("compact_truncated", "the frame ends before its flags")
        flags = data[0]
        if flags & ~KNOWN_FLAGS:
            raise CompactError(
                "compact_unknown_flags", f"flags {flags:#04x} use bits other than key frame, events, root motion and graph"
            )
        key = bool(flags & KEY_FRAME)
        at = [1]
        seq = _varint(data, at, "seq")
        dropped = _varint(data, at, "dropped")
        key_seq = seq - _varint(data, at, "key offset")
        zz = _varint(data, at, "sent_at")
        sent_at = (zz >> 1) ^ -(zz & 1)
        if at[0] + 4 > len(data):
            raise CompactError("compact_truncated", "the frame ends before its clip time")
        (clip_time,) = struct.unpack_from("<f", data, at[0])
        bits = _Bits(data, at[0] + 4)
        if key:
            values = [self._read_joint(bits, j) for j in self.joints]
            self.key, self.key_seq = values, seq
        else:
            if self.key_seq != key_seq:
                raise CompactError(
                    "compact_missing_key_frame",
                    f"a delta frame refers to key frame {key_seq}, and the last key frame seen is {self.key_seq}",
                )
            values = [
                self._read_joint(bits, j) if j["animated"] and bits.read(1) else v for j, v in zip(self.joints, self.key)
            ]
        at[0] = (bits.bit + 7) // 8
        events = self._read_events(data, at) if flags & EVENTS else []
        root_motion = _read_root_motion(data, at) if flags & ROOT_MOTION else None
        graph = self._read_graph(data, at) if flags & GRAPH else None
        if at[0] != len(data):
            raise CompactError("compact_trailing_bytes", f"{len(data) - at[0]} bytes follow the frame's last field")
        t, r, s = self._dequantise(values)
        return Frame(seq, dropped, sent_at, clip_time, key, key_seq, t, r, s, events, root_motion, graph)

    def _read_graph(self, data, at):
        """The graph report section: the state, the transition (0, or from + 1,
        to and alpha), then each evaluated blend node's index and weights."""
        states, nodes = self.graph["states"], self.graph["nodes"]

        def index(value, names, what):
            if value >= len(names):
                raise CompactError("compact_unknown_graph_index", f"graph {what} {value} is not in the layout's {len(names)}")
            return value

        report = {"state": index(_varint(data, at, "graph report"), states, "state"), "transition": None}
        start = _varint(data, at, "graph report")
        if start:
            source = index(start - 1, states, "state")
            target = index(_varint(data, at, "graph report"), states, "state")
            report["transition"] = {"from": source, "to": target, "alpha": _f32s(data, at, 1)[0]}
        weights = []
        for _ in range(_varint(data, at, "graph report")):
            node = index(_varint(data, at, "graph report"), nodes, "node")
            weights.append({"node": node, "weights": _f32s(data, at, nodes[node]["points"])})
        report["weights"] = weights
        return report

    def _read_events(self, data, at):
        """The events section: a count, then indices into the layout's ``events``."""
        events = []
        for _ in range(_varint(data, at, "events")):
            index = _varint(data, at, "events")
            if index >= len(self.events):
                raise CompactError(
                    "compact_unknown_event", f"event {index} is not in the layout's {len(self.events)} events"
                )
            events.append(index)
        return events

    @staticmethod
    def _read_joint(bits, joint):
        largest, rotation = 0, ()
        if "components" in joint:
            largest = joint["largest"] if joint["largest"] is not None else bits.read(2)
            rotation = tuple(bits.read(joint["components"][k][0]) for k in range(4) if k != largest)
        translation = tuple(bits.read(f[0]) for f in joint["translation"])
        scale = tuple(bits.read(f[0]) for f in joint["scale"])
        return largest, rotation, translation, scale

    def _dequantise(self, values):
        n = len(self.joints)
        t = np.empty((n, 3), np.float32)
        r = np.empty((n, 4), np.float32)
        s = np.empty((n, 3), np.float32)
        for i, (joint, (largest, rotation, translation, scale)) in enumerate(zip(self.joints, values)):
            if "constant" in joint:
                r[i] = joint["constant"]
            else:
                others = [k for k in range(4) if k != largest]
                small = [_value(joint["components"][k], u) for k, u in zip(others, rotation)]
                total = small[0] * small[0] + small[1] * small[1] + small[2] * small[2]
                if total < 1.0:
                    big = math.sqrt(1.0 - total)
                else:
                    norm = math.sqrt(total)
                    small, big = [c / norm for c in small], 0.0
                q = [0.0] * 4
                q[largest] = big
                for k, c in zip(others, small):
                    q[k] = c
                r[i] = q  # float64 -> float32: round to nearest, as the other decoders
            t[i] = [_value(f, u) for f, u in zip(joint["translation"], translation)]
            s[i] = [_value(f, u) for f, u in zip(joint["scale"], scale)]
        return t, r, s
