// An inbetween stream on a three.js character: opens a WebSocket stream
// (compact frames by default, docs/compact-frames.md), keeps a small snapshot
// interpolation buffer (buffer.mjs) and, once per rendered frame, puts the
// interpolated pose on the bones (a `SkinnedMesh`'s skeleton) or nodes (any
// `Object3D` hierarchy) of the same names, and a stream's root motion on the
// object itself.
//
//   import { InbetweenPlayer } from "./inbetween-three.mjs";
//   const player = InbetweenPlayer.connect({ server: "ws://127.0.0.1:8080", clip: ID, fps: 20, target: gltf.scene });
//   renderer.setAnimationLoop((now) => { player.update(now); renderer.render(scene, camera); });
//
// It uses only what every three.js `Object3D` has (`name`, `isBone`,
// `traverse`, `position`, `quaternion`, `scale`), so it imports no copy of
// three itself. Browsers cannot set WebSocket headers: a server with a read
// token needs a same-origin proxy that adds it (docs/api.md, Streams).

import { CompactDecoder } from "../js/compact.mjs";
import { SnapshotBuffer, emptyPose } from "./buffer.mjs";
import { matchNames, threeName } from "./names.mjs";

/** The nodes under `target` a stream can drive: a skinned mesh's bones, else every node, bones first. */
export function nodesOf(target) {
  if (target.isSkinnedMesh) return target.skeleton.bones;
  const bones = [];
  const others = [];
  target.traverse((node) => (node.isBone ? bones : others).push(node));
  return [...bones, ...others];
}

/** A clip stream's WebSocket URL: `/v1/clips/{clip}/stream` with `query`. */
export function streamUrl(server, clip, query) {
  const url = new URL(`${server.replace(/\/$/, "")}/v1/clips/${encodeURIComponent(clip)}/stream`);
  for (const [k, v] of Object.entries(query)) url.searchParams.set(k, String(v));
  return url.href;
}

/** One stream playing on one three.js object. */
export class InbetweenPlayer {
  /**
   * Opens `clip`'s stream on `server` (`ws://host:port`) and drives `target`.
   * `encoding`: `compact` (default) or `json`; `query`: more stream
   * parameters (`playback`, `speed`, `max_error`, …); `delayTicks`: how far
   * behind the newest frame to render (2).
   */
  static connect({ server, clip, fps = 30, target, encoding = "compact", query = {}, delayTicks = 2 }) {
    const params = { fps, encoding, ...query };
    const socket = new WebSocket(streamUrl(server, clip, params));
    return new InbetweenPlayer(socket, { fps, target, delayTicks });
  }

  /** Plays the frames of an open `socket` (a clip stream, or a `/v1/stream` after its `open` message). */
  constructor(socket, { fps, target, delayTicks = 2 }) {
    Object.assign(this, { socket, target, fps });
    this.buffer = new SnapshotBuffer({ fps, delayTicks });
    this.decoder = null;
    this.names = null;
    this.pose = null;
    this.bound = null; // [node or null] per joint
    this.frames = 0;
    this.bytes = 0;
    this.shown = null; // the last update's sample: {mode, from, to, alpha, time}
    this.error = null;
    // The object's own placement: root motion is added to it.
    this.origin = { position: target.position.clone(), quaternion: target.quaternion.clone() };
    socket.binaryType = "arraybuffer";
    socket.onmessage = (message) => this.receive(message.data, performance.now());
    socket.onclose = (event) => (this.closed = { code: event.code, reason: event.reason });
  }

  receive(data, now) {
    if (typeof data !== "string") {
      this.bytes += data.byteLength;
      this.take(compactFrame(this.decoder.decode(new Uint8Array(data))), now);
      return;
    }
    this.bytes += data.length;
    const message = JSON.parse(data);
    if (message.error) this.error = message.error;
    else if (message.opened) this.open(message.opened);
    else if (message.layout) this.relayout(message.layout);
    else if (message.pose) this.take(jsonFrame(message, this), now);
  }

  /** The `opened` message: a compact stream's layout, and the joint names. */
  open(opened) {
    if (opened.compact) this.decoder = new CompactDecoder(opened.compact);
    const names = this.decoder?.names ?? opened.joints;
    if (names) this.bind(names);
  }

  /**
   * A new layout mid-stream (docs/compact-frames.md, "A new layout"): the
   * frames after it decode in it. The skeleton and the buffered frames stay,
   * so the pose interpolates on from the last frame of the old layout to the
   * first of the new without a jump.
   */
  relayout(layout) {
    this.decoder.relayout(layout);
  }

  bind(names) {
    this.names = names;
    this.pose = emptyPose(names.length);
    const nodes = nodesOf(this.target);
    const index = matchNames(
      names,
      nodes.map((n) => n.name),
      threeName,
    );
    this.bound = index.map((i) => (i < 0 ? null : nodes[i]));
    this.missing = names.filter((_, j) => index[j] < 0);
  }

  /** Keeps a frame; its events (`{time, name}`, in the order crossed) go to `onevents` as they arrive. */
  take(frame, now) {
    if (frame.events.length > 0) this.onevents?.(frame.events, frame);
    this.frames++;
    this.buffer.push(frame, now);
  }

  /** Puts the pose at `nowMs` (`performance.now()`, or the animation loop's time) on the target. */
  update(nowMs = performance.now()) {
    const time = this.buffer.renderTime(nowMs);
    if (time === null || !this.bound) return null;
    const sample = this.buffer.sample(time, this.pose);
    this.apply(this.pose);
    this.shown = { ...sample, time };
    return this.shown;
  }

  apply(pose) {
    const { translations: t, rotations: r, scales: s } = pose;
    this.bound.forEach((node, j) => {
      if (!node) return;
      node.position.set(t[3 * j], t[3 * j + 1], t[3 * j + 2]);
      node.quaternion.set(r[4 * j], r[4 * j + 1], r[4 * j + 2], r[4 * j + 3]);
      node.scale.set(s[3 * j], s[3 * j + 1], s[3 * j + 2]);
    });
    if (pose.hasRoot) this.applyRoot(pose.root);
  }

  /** Root motion's total ([x, y, z] travelled, yaw turned about +Y) on top of the object's own placement. */
  applyRoot([x, y, z, yaw]) {
    const { position, quaternion } = this.origin;
    this.target.position.set(position.x + x, position.y + y, position.z + z);
    const half = yaw / 2;
    this.target.quaternion.set(0, Math.sin(half), 0, Math.cos(half)).premultiply(quaternion);
  }

  /** Sends a control (`{op: "pause"}`, `{op: "seek", time}`, …: docs/api.md, Streams). */
  send(control) {
    this.socket.send(JSON.stringify(control));
  }

  close() {
    this.socket.close(1000);
  }
}

/** A decoded compact frame, its root motion's total as the buffer takes it. */
function compactFrame(frame) {
  const total = frame.rootMotion?.total;
  return { ...frame, root: total ?? null };
}

/** A JSON frame as flat arrays (the decoder's shape), binding the names from the first one. */
function jsonFrame(message, player) {
  const joints = message.pose.joints;
  if (!player.names) player.bind(joints.map((j) => j.name));
  const total = message.pose.root_motion?.total;
  return {
    seq: message.seq,
    clipTime: message.clip_time,
    translations: joints.flatMap((j) => j.translation),
    rotations: joints.flatMap((j) => j.rotation),
    scales: joints.flatMap((j) => j.scale),
    root: total ? [...total.translation, total.yaw] : null,
    events: message.events ?? [],
  };
}
