#!/usr/bin/env python3
"""Drives a stored graph (docs/graphs.md) from a game-like loop.

Stores the graph file (its `name:X` clips looked up on the server), opens a
WebSocket stream of it with its report, and every second sends a `set`
control, as a game's update loop would: the first float parameter walks from
its minimum to its maximum, and a trigger, if the graph has one, fires half
way. Each second's frame is printed with the state and the blend weights.

    python3 examples/clients/python/graph.py --http http://127.0.0.1:8080 \
        --import examples/gltf/Fox/Fox.glb examples/graphs/fox-locomotion.json

Exits non-zero unless every blend1d over the walked parameter shows the
weights docs/graphs.md defines for the value set (once it has landed), and
the graph went through more than one state.
"""

import argparse
import asyncio
import json
import pathlib
import sys
import urllib.parse

import websockets

from inbetween_client import Rest


def blend1d(points, v):
    """A blend1d's weights at `v`: the two neighbours by linear share, clamped at the ends."""
    ats = [p["at"] for p in points]
    w = [0.0] * len(ats)
    if v <= ats[0]:
        w[0] = 1.0
    elif v >= ats[-1]:
        w[-1] = 1.0
    else:
        i = next(k for k in range(len(ats) - 1) if ats[k] <= v < ats[k + 1])
        u = (v - ats[i]) / (ats[i + 1] - ats[i])
        w[i], w[i + 1] = 1.0 - u, u
    return w


def with_clip_ids(rest, doc):
    """`doc` with every `"clip": "name:X"` replaced by the id of the one clip named X."""
    if isinstance(doc, list):
        return [with_clip_ids(rest, v) for v in doc]
    if not isinstance(doc, dict):
        return doc
    out = {}
    for key, value in doc.items():
        if key == "clip" and isinstance(value, str) and value.startswith("name:"):
            clips = rest.call("GET", "/v1/clips?name=" + urllib.parse.quote(value[5:]))["clips"]
            if len(clips) != 1:
                sys.exit(f"{len(clips)} clips are named {value[5:]}: import them first")
            out[key] = clips[0]["id"]
        else:
            out[key] = with_clip_ids(rest, value)
    return out


class Checker:
    """Checks each frame's blend1d weights against the value in force."""

    def __init__(self, doc, parameter, fps):
        self.blends = {n: b["blend1d"]["points"] for n, b in doc["nodes"].items()
                       if b.get("blend1d", {}).get("parameter") == parameter}
        self.fps, self.value, self.before, self.sent_at = fps, None, None, -1
        self.checked, self.failures, self.states = 0, 0, set()

    def sent(self, value, seq):
        self.before, self.value, self.sent_at = self.value, value, seq

    def frame(self, frame):
        report = frame.get("graph") or frame["pose"].get("graph") or {}
        self.states.add(report.get("state"))
        if self.value is None:
            return
        # A set lands on the tick after the server reads it: frames on their way show the value before.
        values = [self.value] if frame["seq"] > self.sent_at + self.fps / 2 else [self.value, self.before]
        for node, points in self.blends.items():
            got = report.get("weights", {}).get(node)
            if got is None:
                continue
            self.checked += 1
            if all(max(abs(g - w) for g, w in zip(got, blend1d(points, v))) > 1e-6 for v in values if v is not None):
                self.failures += 1
                print(f"seq {frame['seq']}: {node} {got}, not blend1d at {values}", file=sys.stderr)


async def drive(args, rest, graph, doc):
    params = doc.get("parameters", {})
    name, spec = next((n, p) for n, p in params.items() if p["type"] == "float")
    trigger = next((n for n, p in params.items() if p["type"] == "trigger"), None)
    checker = Checker(doc, name, args.fps)
    url = args.http.replace("http", "ws", 1).rstrip("/") + "/v1/stream"
    async with websockets.connect(url, additional_headers=rest.headers) as ws:
        await ws.send(json.dumps({"op": "open", "motion": {"layers": [{"graph": graph["id"]}]},
                                  "fps": args.fps, "report": True}))
        seq, step = -1, 0
        async for message in ws:
            frame = json.loads(message)
            if "error" in frame:
                sys.exit(f"refused: {frame['error']}")
            if "seq" not in frame:
                continue
            seq = frame["seq"]
            checker.frame(frame)
            if seq % args.fps:
                continue
            report = frame.get("graph") or frame["pose"].get("graph") or {}
            print(f"seq={seq} {name}={checker.value} state={report.get('state')} weights={report.get('weights')}")
            if step > 10:
                await ws.send(json.dumps({"op": "stop"}))
                continue
            value = spec["min"] + (spec["max"] - spec["min"]) * step / 10
            settings = {name: value, **({trigger: True} if trigger and step == 5 else {})}
            checker.sent(value, seq)
            await ws.send(json.dumps({"op": "set", "parameters": settings}))
            step += 1
    return checker


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("graph", type=pathlib.Path, help="a graph document (docs/graphs.md)")
    parser.add_argument("--http", default="http://127.0.0.1:8080")
    parser.add_argument("--token")
    parser.add_argument("--fps", type=int, default=30)
    parser.add_argument("--import", dest="imports", type=pathlib.Path, help="a glTF/BVH file to import first")
    args = parser.parse_args()
    rest = Rest(args.http, args.token)
    if args.imports:
        rest.call("POST", "/v1/clips/import?replace=true", args.imports.read_bytes())
    doc = with_clip_ids(rest, json.loads(args.graph.read_text()))
    graph = rest.call("POST", "/v1/graphs?replace=true", doc)
    print(f"graph {graph['name']} {graph['id']} v{graph['version']}", file=sys.stderr)
    checker = asyncio.run(drive(args, rest, graph, doc))
    print(f"{checker.checked} reports checked against blend1d, {checker.failures} off; "
          f"states seen: {sorted(s for s in checker.states if s)}", file=sys.stderr)
    if checker.failures or not checker.checked or len(checker.states) < 2:
        sys.exit(1)


if __name__ == "__main__":
    main()
