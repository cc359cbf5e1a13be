"""The Python compact decoder against docs/compact-frames/: every frame of every
vector decodes to exactly the pose the Rust encoder quantised.
Run: python3 -m unittest discover -s examples/clients/python -p 'test_*.py'"""

import json
import pathlib
import unittest

import numpy as np

from compact import CompactDecoder, CompactError

VECTORS = pathlib.Path(__file__).resolve().parents[3] / "docs" / "compact-frames"


def load():
    return [json.loads(p.read_text()) for p in sorted(VECTORS.glob("*.json"))]


def as_f32(value):
    """A vector's report with its floats rounded to f32, as a frame sends them."""
    if isinstance(value, float):
        return float(np.float32(value))
    if isinstance(value, list):
        return [as_f32(v) for v in value]
    if isinstance(value, dict):
        return {k: as_f32(v) for k, v in value.items()}
    return value


class CompactVectors(unittest.TestCase):
    def test_every_frame_decodes_to_the_stored_pose_exactly(self):
        vectors = load()
        self.assertGreaterEqual(len(vectors), 5)
        for vector in vectors:
            decoder = CompactDecoder(vector["layout"])
            for frame in vector["frames"]:
                if "layout" in frame:  # a new layout mid-stream
                    decoder.relayout(frame["layout"])
                got = decoder.decode(bytes.fromhex(frame["hex"]))
                with self.subTest(vector=vector["name"], seq=frame["seq"]):
                    self.assertEqual((got.key, got.seq, got.dropped), (frame["key"], frame["seq"], frame["dropped"]))
                    self.assertEqual(got.sent_at_unix_nanos, int(frame["sent_at_unix_nanos"]))
                    self.assertEqual(got.clip_time, float(np.float32(frame["clip_time"])))
                    for name in ("rotations", "translations", "scales"):
                        expected = np.array(frame["pose"][name], dtype=np.float32)
                        np.testing.assert_array_equal(getattr(got, name), expected, err_msg=name)
                    self.assertEqual(got.events, frame.get("events", []))
                    root = frame.get("root_motion")
                    f32 = lambda values: [float(np.float32(v)) for v in values]
                    expected = root and {"delta": f32(root["delta"]), "total": f32(root["total"])}
                    self.assertEqual(got.root_motion, expected)
                    self.assertEqual(got.graph, frame.get("graph") and as_f32(frame["graph"]))

    def test_a_delta_frame_without_its_key_frame_is_refused(self):
        vector = next(v for v in load() if v["name"] == "bench20")
        decoder = CompactDecoder(vector["layout"])
        with self.assertRaises(CompactError) as refused:
            decoder.decode(bytes.fromhex(vector["frames"][1]["hex"]))
        self.assertEqual(refused.exception.code, "compact_missing_key_frame")
        key = bytes.fromhex(vector["frames"][0]["hex"])
        for bad, code in [(key[:-1], "compact_truncated"), (key + b"\0", "compact_trailing_bytes")]:
            with self.assertRaises(CompactError) as refused:
                decoder.decode(bad)
            self.assertEqual(refused.exception.code, code)
        with self.assertRaises(CompactError) as refused:
            CompactDecoder(vector["layout"]).decode(bytes([key[0] | 16]) + key[1:])
        self.assertEqual(refused.exception.code, "compact_unknown_flags")

    def test_an_unknown_event_and_a_short_root_motion_are_refused(self):
        vector = next(v for v in load() if v["name"] == "stepping")
        key = bytes.fromhex(vector["frames"][0]["hex"])  # events [0], then root motion
        self.assertEqual(key[-34], 1, "one event")
        unknown = key[:-33] + bytes([len(vector["layout"]["events"])]) + key[-32:]
        for bad, code in [(unknown, "compact_unknown_event"), (key[:-1], "compact_truncated")]:
            with self.assertRaises(CompactError) as refused:
                CompactDecoder(vector["layout"]).decode(bad)
            self.assertEqual(refused.exception.code, code)

    def test_a_new_layout_forgets_the_old_key_frame(self):
        vector = next(v for v in load() if v["name"] == "relayout")
        frames = [bytes.fromhex(f["hex"]) for f in vector["frames"]]
        decoder = CompactDecoder(vector["layout"])
        decoder.decode(frames[0])
        decoder.decode(frames[1])
        decoder.relayout(vector["frames"][2]["layout"])
        with self.assertRaises(CompactError) as refused:
            decoder.decode(frames[3])
        self.assertEqual(refused.exception.code, "compact_missing_key_frame")
        self.assertTrue(decoder.decode(frames[2]).key)
        self.assertFalse(decoder.decode(frames[3]).key)

    def test_graph_indices_past_the_layouts_graph_and_a_short_report_are_refused(self):
        vector = next(v for v in load() if v["name"] == "graph-report")
        key, delta = (bytes.fromhex(f["hex"]) for f in vector["frames"][:2])
        at = len(delta) - 17  # the state: then from + 1, to, alpha, one node, its index and two weights
        self.assertEqual(delta[at], 2)
        for offset, value in [(0, 3), (1, 4), (2, 3), (8, 2)]:
            decoder = CompactDecoder(vector["layout"])
            decoder.decode(key)
            with self.assertRaises(CompactError) as refused:
                decoder.decode(delta[: at + offset] + bytes([value]) + delta[at + offset + 1 :])
            self.assertEqual(refused.exception.code, "compact_unknown_graph_index", (offset, value))
        decoder = CompactDecoder(vector["layout"])
        decoder.decode(key)
        with self.assertRaises(CompactError) as refused:
            decoder.decode(delta[:-1])
        self.assertEqual(refused.exception.code, "compact_truncated")


if __name__ == "__main__":
    unittest.main()
