#!/usr/bin/env python3
"""A Python client of inbetween over all three of its protocols.

Uploads a clip over REST, samples one pose over REST and the same pose over
gRPC (they must agree), then plays the clip over a WebSocket for a few frames,
printing each and checking its clip time against the schedule (docs/api.md),
and plays it again in compact frames (docs/compact-frames.md) beside a JSON
stream of the same ticks, each decoded pose within the stated bound.

    python3 -m pip install -r examples/clients/python/requirements.txt
    python3 examples/clients/python/inbetween_client.py \
        --http http://127.0.0.1:8080 --grpc 127.0.0.1:50051 examples/wave.json

Exits non-zero when the server answers something a client cannot rely on.
"""

import argparse
import asyncio
import json
import math
import pathlib
import sys
import tempfile
import urllib.error
import urllib.request

import grpc
import websockets
from grpc_tools import protoc

PROTO_ROOT = pathlib.Path(__file__).resolve().parents[3] / "proto"


def load_stubs():
    """Compiles animation.proto into a temporary package and imports it."""
    out = tempfile.mkdtemp(prefix="inbetween-stubs-")
    proto = "inbetween/v1/animation.proto"
    args = ["protoc", f"-I{PROTO_ROOT}", f"-I{protoc._get_resource_file_name('grpc_tools', '_proto')}",
            f"--python_out={out}", f"--grpc_python_out={out}", proto]
    if protoc.main(args) != 0:
        sys.exit(f"could not compile {PROTO_ROOT / proto}")
    sys.path.insert(0, out)
    from inbetween.v1 import animation_pb2, animation_pb2_grpc  # noqa: E402  (generated just now)
    return animation_pb2, animation_pb2_grpc


class Rest:
    """The few REST calls this example needs, with the standard library alone."""

    def __init__(self, base, token=None):
        self.base = base.rstrip("/")
        self.headers = {"Authorization": f"Bearer {token}"} if token else {}

    def call(self, method, path, body=None):
        """`body`: a JSON value, or bytes sent as they are (a file to import)."""
        raw = isinstance(body, bytes)
        data = body if raw else json.dumps(body).encode() if body is not None else None
        kind = "application/octet-stream" if raw else "application/json"
        headers = dict(self.headers, **({"Content-Type": kind} if data else {}))
        req = urllib.request.Request(self.base + path, data=data, method=method, headers=headers)
        try:
            with urllib.request.urlopen(req) as resp:
                return json.load(resp)
        except urllib.error.HTTPError as err:  # a problem body (RFC 9457) says what went wrong
            sys.exit(f"{method} {path}: {err.code} {err.read().decode()}")


def grpc_pose(stubs, target, clip_id, t, token=None):
    pb, pb_grpc = stubs
    target = target.removeprefix("http://")  # grpc wants host:port
    with grpc.insecure_channel(target) as channel:
        metadata = [("authorization", f"Bearer {token}")] if token else []
        return pb_grpc.AnimationStub(channel).Sample(pb.SampleRequest(clip_id=clip_id, time=t), metadata=metadata)


def compare(rest_pose, grpc_pose_msg):
    """REST's joints against gRPC's packed arrays: the same f32 values."""
    names = list(grpc_pose_msg.joint_names)
    assert names == [j["name"] for j in rest_pose["joints"]], names
    for i, joint in enumerate(rest_pose["joints"]):
        packed = grpc_pose_msg.rotations[4 * i:4 * i + 4]
        assert all(math.isclose(a, b, abs_tol=1e-6) for a, b in zip(joint["rotation"], packed)), (joint, packed)
        assert math.isclose(sum(q * q for q in packed), 1.0, abs_tol=1e-5), "unit quaternion"


async def play(http_base, summary, fps, frames, token=None):
    """Reads `frames` frames of a looping stream from the clip's start and
    checks each clip time against the schedule: start + (seq/fps mod duration)."""
    start, duration = summary["start"], summary["duration"]
    url = http_base.replace("http", "ws", 1) + f"/v1/clips/{summary['id']}/stream?fps={fps}&start={start}&playback=loop"
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    async with websockets.connect(url, additional_headers=headers) as ws:
        for _ in range(frames):
            frame = json.loads(await ws.recv())
            root = frame["pose"]["joints"][0]
            print(f"seq={frame['seq']} clip_time={frame['clip_time']:.4f} dropped={frame['dropped']} "
                  f"events={[e['name'] for e in frame['events']]} root={[round(v, 4) for v in root['translation']]}")
            expected = start + math.fmod(frame["seq"] / fps, duration)
            assert math.isclose(frame["clip_time"], expected, abs_tol=1e-4), (frame["clip_time"], expected)
        await ws.send(json.dumps({"op": "stop"}))


async def play_compact(http_base, summary, fps, frames, token=None, max_error=1e-4):
    """A compact stream and a JSON stream of the same ticks: every compact
    frame decodes (compact.py) to within `max_error` of the JSON pose, each
    joint's translation directly, its rotation as the angle that moves a
    point at the layout's `distance`."""
    from compact import CompactDecoder

    base = http_base.replace("http", "ws", 1) + f"/v1/clips/{summary['id']}/stream"
    query = f"fps={fps}&start={summary['start']}&playback=loop&max_frames={frames}"
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    async with websockets.connect(f"{base}?{query}&encoding=compact&max_error={max_error}",
                                  additional_headers=headers) as compact, \
            websockets.connect(f"{base}?{query}", additional_headers=headers) as plain:
        layout = json.loads(await compact.recv())["opened"]["compact"]
        decoder = CompactDecoder(layout)
        decoded = {}
        for _ in range(frames):
            frame = decoder.decode(await compact.recv())
            decoded[frame.seq] = frame
        reference = {}
        for _ in range(frames):
            frame = json.loads(await plain.recv())
            reference[frame["seq"]] = frame["pose"]["joints"]
    keys = sum(1 for f in decoded.values() if f.key)
    worst = 0.0
    for seq in decoded.keys() & reference.keys():
        for j, joint in enumerate(reference[seq]):
            got = decoded[seq]
            worst = max(worst, max(abs(a - b) for a, b in zip(joint["translation"], got.translations[j])))
            # The angle between two unit quaternions is about twice their distance (sign aligned).
            sign = math.copysign(1.0, sum(float(a) * b for a, b in zip(got.rotations[j], joint["rotation"])))
            gap = math.dist([float(a) for a in got.rotations[j]], [sign * b for b in joint["rotation"]])
            worst = max(worst, 2 * gap * layout["distance"])
    assert worst <= max_error * 1.01, (worst, max_error)
    assert keys >= 1 and len(decoded) == frames, (keys, len(decoded))
    print(f"compact: {len(decoded)} frames ({keys} key), worst {worst:.2e} m of {max_error} against the JSON stream")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clip", help="a clip document (JSON), e.g. examples/wave.json")
    parser.add_argument("--http", default="http://127.0.0.1:8080")
    parser.add_argument("--grpc", default="127.0.0.1:50051")
    parser.add_argument("--token", help="a bearer token when the server has tokens configured")
    parser.add_argument("--fps", type=int, default=30)
    parser.add_argument("--frames", type=int, default=15)
    args = parser.parse_args()

    rest = Rest(args.http, args.token)
    summary = rest.call("POST", "/v1/clips?replace=true", json.loads(pathlib.Path(args.clip).read_text()))
    print(f"uploaded {summary['name']!r} as {summary['id']}: {summary['joints']} joints, "
          f"{summary['start']}..{summary['end']} s")
    t = (summary["start"] + summary["end"]) / 2
    pose = rest.call("GET", f"/v1/clips/{summary['id']}/pose?t={t}")
    compare(pose, grpc_pose(load_stubs(), args.grpc, summary["id"], t, args.token))
    print(f"pose at t={t}: REST and gRPC agree on {len(pose['joints'])} joints")
    asyncio.run(play(args.http, summary, args.fps, args.frames, args.token))
    asyncio.run(play_compact(args.http, summary, args.fps, 2 * args.fps + 5, args.token))


if __name__ == "__main__":
    main()
