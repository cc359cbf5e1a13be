// The snapshot interpolation buffer and its slerp, against hand-computed
// rotations and times. Run: node --test examples/clients/three/tests/
import { test } from "node:test";
import assert from "node:assert/strict";

import { SnapshotBuffer, emptyPose, lerp, slerp } from "../buffer.mjs";

const close = (got, want, eps = 1e-12, what = "") =>
  want.forEach((w, k) => assert.ok(Math.abs(got[k] - w) <= eps, `${what}[${k}]: ${got[k]} against ${w}`));

/** The unit quaternion of `deg` degrees about +Z, [x, y, z, w]. */
const aboutZ = (deg) => [0, 0, Math.sin((deg * Math.PI) / 360), Math.cos((deg * Math.PI) / 360)];

test("slerp turns at a constant rate along the shorter arc, and past its end when extrapolating", () => {
  const out = new Float64Array(4);
  for (const [t, deg] of [[0, 0], [1 / 3, 30], [0.5, 45], [1, 90], [1.5, 135], [-0.5, -45]]) {
    slerp(out, 0, aboutZ(0), 0, aboutZ(90), 0, t);
    close(out, aboutZ(deg), 1e-12, `t = ${t}`);
  }
  // -q is the same rotation as q: the arc from 0° to -(90°) is still the 90° one, not the 270° one.
  slerp(out, 0, aboutZ(0), 0, aboutZ(90).map((c) => -c), 0, 0.5);
  close(out, aboutZ(45), 1e-12, "negated end");
  // Two rotations a hair apart: no division by sin θ ≈ 0, a unit result between them.
  const near = aboutZ(1e-7);
  slerp(out, 0, aboutZ(0), 0, near, 0, 0.5);
  close(out, aboutZ(0.5e-7), 1e-15, "nearly equal");
  assert.ok(Math.abs(Math.hypot(...out) - 1) < 1e-15);
});

test("lerp writes between offsets", () => {
  const out = new Float64Array(5);
  lerp(out, 2, [9, 1, 2, 3], 1, [0, 3, 6, 7], 0, 3, 0.25);
  assert.deepEqual([...out], [0, 0, 0.75, 2.25, 3.75]);
});

/** A one-joint frame: translation x = 10·seq, rotation 30°·seq about Z, scale 1 + seq. */
const frame = (seq) => ({
  seq,
  clipTime: seq / 20,
  translations: [10 * seq, 0, 0],
  rotations: aboutZ(30 * seq),
  scales: [1 + seq, 1, 1],
});

test("the render time runs two ticks behind the earliest arrival, and the pose is interpolated at it", () => {
  const buffer = new SnapshotBuffer({ fps: 20 });
  // seq k is due at k·50 ms; arrivals at 1000 ms + 50 k + jitter (frame 2 the least late).
  const arrivals = [1012, 1065, 1105, 1170];
  arrivals.forEach((at, seq) => buffer.push(frame(seq), at));
  // Least lateness: 1105 − 100 = 1005 ms, crept by 1 ms a second over the 65 ms to the next arrival.
  // Two ticks of delay: render time = now − 1.005065 − 0.1.
  assert.ok(Math.abs(buffer.renderTime(1230) - (0.125 - 0.000065)) < 1e-12);
  const pose = emptyPose(1);
  const shown = buffer.sample(0.125, pose); // between seq 2 (0.10 s) and seq 3 (0.15 s), halfway
  assert.equal(shown.mode, "interpolate");
  assert.deepEqual([shown.from.seq, shown.to.seq], [2, 3]);
  assert.ok(Math.abs(shown.alpha - 0.5) < 1e-12);
  close(pose.translations, [25, 0, 0], 1e-12, "translation");
  close(pose.rotations, aboutZ(75), 1e-12, "rotation");
  close(pose.scales, [3.5, 1, 1], 1e-12, "scale");
  assert.equal(pose.hasRoot, false);
});

test("a late frame is extrapolated for one tick, then held", () => {
  const buffer = new SnapshotBuffer({ fps: 20 });
  [0, 1, 2].forEach((seq) => buffer.push(frame(seq), 50 * seq));
  const pose = emptyPose(1);
  // Half a tick past seq 2 (0.10 s): along 1 → 2 for 1.5 ticks.
  let shown = buffer.sample(0.125, pose);
  assert.deepEqual([shown.mode, shown.from.seq, shown.to.seq], ["extrapolate", 1, 2]);
  close(pose.translations, [25, 0, 0], 1e-12);
  close(pose.rotations, aboutZ(75), 1e-12);
  // Three ticks past: held where one tick of extrapolation ends (seq 2 + 1 tick = 90°).
  for (const time of [0.15, 0.25, 10]) {
    shown = buffer.sample(time, pose);
    assert.equal(shown.mode, time <= 0.15 ? "extrapolate" : "hold", `at ${time}`);
    close(pose.translations, [30, 0, 0], 1e-12);
    close(pose.rotations, aboutZ(90), 1e-12);
  }
  // The late frame arrives: interpolation again, across the dropped tick too.
  buffer.push(frame(4), 260);
  shown = buffer.sample(0.15, pose);
  assert.deepEqual([shown.mode, shown.from.seq, shown.to.seq], ["interpolate", 2, 4]);
  close(pose.translations, [30, 0, 0], 1e-12);
});

test("before the oldest frame, or with one frame, the pose is held", () => {
  const buffer = new SnapshotBuffer({ fps: 10 });
  const pose = emptyPose(1);
  assert.equal(buffer.sample(0, pose), null);
  assert.equal(buffer.renderTime(0), null);
  buffer.push(frame(5), 0);
  assert.equal(buffer.sample(99, pose).mode, "hold");
  close(pose.translations, [50, 0, 0]);
  buffer.push(frame(6), 100);
  assert.equal(buffer.sample(0.2, pose).mode, "hold");
  close(pose.translations, [50, 0, 0]);
});

test("the buffer keeps its capacity, and starts again when seq does (a new stream)", () => {
  const buffer = new SnapshotBuffer({ fps: 20, capacity: 3 });
  for (let seq = 0; seq < 10; seq++) buffer.push(frame(seq), 50 * seq + 7);
  assert.deepEqual(
    buffer.frames.map((f) => f.seq),
    [7, 8, 9],
  );
  buffer.push(frame(0), 9000);
  assert.deepEqual(
    buffer.frames.map((f) => f.seq),
    [0],
  );
  assert.ok(Math.abs(buffer.renderTime(9000) - -0.1) < 1e-12, "the clock starts again at the new stream's lateness");
});

test("the clock estimate follows a network that got slower, a millisecond a second", () => {
  const buffer = new SnapshotBuffer({ fps: 10, delayTicks: 0 });
  buffer.push(frame(0), 0);
  // From seq 1 on, every frame is 200 ms later than seq 0 was.
  for (let seq = 1; seq <= 50; seq++) buffer.push(frame(seq), 100 * seq + 200);
  // 5 s of arrivals since seq 0 (the clock read 5.2 s): the offset rose 5.2 ms, still under 200 ms.
  assert.ok(Math.abs(buffer.offset - 0.0052) < 1e-12, `${buffer.offset}`);
});

test("root motion is interpolated when both frames carry it", () => {
  const buffer = new SnapshotBuffer({ fps: 10 });
  buffer.push({ ...frame(0), root: [0, 0, 0, 0] }, 0);
  buffer.push({ ...frame(1), root: [1, 0, 2, 0.5] }, 100);
  const pose = emptyPose(1);
  buffer.sample(0.025, pose);
  assert.equal(pose.hasRoot, true);
  close(pose.root, [0.25, 0, 0.5, 0.125]);
});
