// Unit tests of the viewer's maths (../math.js): `node --test` on this file
// (tests/service/viewer/units.rs runs it under `cargo test`). Not served:
// only the files viewer.rs lists are.
import { test } from "node:test";
import assert from "node:assert/strict";

import {
  IDENTITY, IDENTITY_QUAT, EASES, applyTransform, cameraBasis, composeTransforms, conj, cross, dot, eulerDegrees,
  mat4Multiply, modelTransforms, nearestBranch, nearestIndex, normalize, qmul, rotate, sub, toCamera, toScreen, trs,
  turn, unapplyTransform, unease, unwrapSeries, viewProjection, yawOf,
} from "../math.js";

const EPS = 1e-12;

function close(actual, expected, eps = EPS, what = "") {
  assert.equal(actual.length, expected.length, `${what} length`);
  actual.forEach((a, i) => assert.ok(Math.abs(a - expected[i]) <= eps, `${what}[${i}]: ${a} vs ${expected[i]} (${actual} vs ${expected})`));
}

/// The unit quaternion of `degrees` about the (unit) `axis`.
function axisAngle(axis, degrees) {
  const h = (degrees * Math.PI) / 360;
  return [axis[0] * Math.sin(h), axis[1] * Math.sin(h), axis[2] * Math.sin(h), Math.cos(h)];
}
const X = [1, 0, 0], Y = [0, 1, 0], Z = [0, 0, 1];

/// A small deterministic generator (the tests are the same every run).
function random(seed) {
  let s = seed >>> 0;
  return () => {
    s = (Math.imul(s, 1664525) + 1013904223) >>> 0;
    return s / 2 ** 32;
  };
}
const rnd = random(28);
const randomVector = (k = 4) => [0, 1, 2].map(() => (rnd() * 2 - 1) * k);
function randomQuat() {
  const q = [0, 1, 2, 3].map(() => rnd() * 2 - 1);
  const n = Math.hypot(...q);
  return q.map((c) => c / n);
}
const randomTransform = (uniform = false) => {
  const k = 0.5 + rnd() * 1.5;
  return { t: randomVector(), q: randomQuat(), s: uniform ? [k, k, k] : [0.5 + rnd(), 0.5 + rnd(), 0.5 + rnd()] };
};
const transformPoint = (m, p) => [0, 1, 2].map((r) => m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r]);

test("vectors: hand-computed products", () => {
  assert.deepEqual(sub([3, 5, 7], [1, 1, 2]), [2, 4, 5]);
  assert.equal(dot([1, 2, 3], [4, -5, 6]), 12);
  assert.deepEqual(cross(X, Y), Z);
  assert.deepEqual(cross(Y, Z), X);
  assert.deepEqual(cross([1, 2, 3], [4, 5, 6]), [-3, 6, -3]);
  assert.deepEqual(normalize([3, 0, 4]), [0.6, 0, 0.8]);
  assert.deepEqual(normalize([0, 0, 0]), [0, 0, 0]);
});

test("qmul: hand-computed products, identity, associativity", () => {
  const i = [1, 0, 0, 0], j = [0, 1, 0, 0], k = [0, 0, 1, 0];
  assert.deepEqual(qmul(i, j), k);
  assert.deepEqual(qmul(j, i), [0, 0, -1, 0]);
  assert.deepEqual(qmul(i, i), [0, 0, 0, -1]);
  assert.deepEqual(qmul(qmul(i, j), k), [0, 0, 0, -1]); // ijk = -1
  for (let n = 0; n < 50; n++) {
    const a = randomQuat(), b = randomQuat(), c = randomQuat();
    close(qmul(a, IDENTITY_QUAT), a);
    close(qmul(IDENTITY_QUAT, a), a);
    close(qmul(qmul(a, b), c), qmul(a, qmul(b, c)), 1e-14);
    assert.ok(Math.abs(Math.hypot(...qmul(a, b)) - 1) < 1e-14, "a product of unit quaternions is unit");
    close(qmul(a, conj(a)), [0, 0, 0, 1], 1e-14, "q·q* = 1");
  }
});

test("rotate: quarter turns about each axis", () => {
  close(rotate(axisAngle(Z, 90), X), Y, 1e-15);
  close(rotate(axisAngle(X, 90), Y), Z, 1e-15);
  close(rotate(axisAngle(Y, 90), Z), X, 1e-15);
  close(rotate(axisAngle(Y, 180), [1, 2, 3]), [-1, 2, -3], 1e-15);
  close(rotate(IDENTITY_QUAT, [1, 2, 3]), [1, 2, 3], 0);
});

test("rotate: keeps lengths, composes as qmul, undone by the conjugate", () => {
  for (let n = 0; n < 50; n++) {
    const a = randomQuat(), b = randomQuat(), v = randomVector();
    const r = rotate(a, v);
    assert.ok(Math.abs(Math.hypot(...r) - Math.hypot(...v)) < 1e-13);
    close(rotate(qmul(a, b), v), rotate(a, rotate(b, v)), 1e-13);
    close(rotate(conj(a), r), v, 1e-13);
    close(rotate(a.map((c) => -c), v), r, 1e-13, "q and -q are the same rotation");
  }
});

test("yawOf and turn: a heading about +y", () => {
  for (const degrees of [0, 30, 90, 135, -60, -170]) {
    const q = axisAngle(Y, degrees);
    assert.ok(Math.abs(yawOf(q) - (degrees * Math.PI) / 180) < 1e-14, `${degrees}°`);
    close(turn(yawOf(q), [1, 2, 3]), rotate(q, [1, 2, 3]), 1e-14);
  }
  close(turn(Math.PI / 2, X), [0, 0, -1], 1e-15);
});

test("transforms: apply, unapply and compose", () => {
  const f = { t: [1, 2, 3], q: axisAngle(Z, 90), s: [2, 2, 2] };
  close(applyTransform(f, [1, 0, 0]), [1, 4, 3], 1e-15); // scaled to 2, turned to +y, moved
  close(applyTransform(IDENTITY, [4, 5, 6]), [4, 5, 6], 0);
  for (let n = 0; n < 50; n++) {
    const a = randomTransform(), u = randomTransform(true), b = randomTransform(), x = randomVector();
    close(unapplyTransform(a, applyTransform(a, x)), x, 1e-12, "round trip");
    close(applyTransform(a, unapplyTransform(a, x)), x, 1e-12, "round trip back");
    // Exact under a uniformly scaled parent (else the product would shear, which a transform cannot hold).
    close(applyTransform(composeTransforms(u, b), x), applyTransform(u, applyTransform(b, x)), 1e-12, "compose");
    // An unrotated child composes exactly under any parent.
    const still = { ...b, q: IDENTITY_QUAT };
    close(applyTransform(composeTransforms(a, still), x), applyTransform(a, applyTransform(still, x)), 1e-12, "compose, unrotated child");
    const ab = composeTransforms(a, b);
    close(ab.s, a.s.map((c, k) => c * b.s[k]), 0);
  }
});

test("modelTransforms: down the hierarchy, roots and out-of-order parents as they are", () => {
  const root = { t: [0, 1, 0], q: axisAngle(Y, 90), s: [1, 1, 1] };
  const child = { t: [0, 0, 1], q: IDENTITY_QUAT, s: [1, 1, 1] };
  const grandchild = { t: [0, 0, 2], q: axisAngle(X, 90), s: [1, 1, 1] };
  const model = modelTransforms([root, child, grandchild], [-1, 0, 1]);
  assert.equal(model[0], root);
  close(model[1].t, [1, 1, 0], 1e-15); // +z turned 90° about y is +x
  close(model[2].t, [3, 1, 0], 1e-15);
  close(model[2].q, qmul(root.q, grandchild.q), 0);
  // A parent after its child: the child is taken as a root.
  const out = modelTransforms([child, root], [1, -1]);
  assert.equal(out[0], child);
});

test("trs: a hand-computed matrix, and the same map as applyTransform", () => {
  const m = trs([1, 2, 3], axisAngle(Z, 90), [2, 3, 4]);
  close(m, [0, 2, 0, 0, -3, 0, 0, 0, 0, 0, 4, 0, 1, 2, 3, 1], 1e-15);
  for (let n = 0; n < 50; n++) {
    const f = randomTransform(), x = randomVector();
    close(transformPoint(trs(f.t, f.q, f.s), x), applyTransform(f, x), 1e-12);
  }
});

test("mat4Multiply: identity, and trs(a)·trs(b) = trs(a∘b) under uniform scale", () => {
  const I = trs([0, 0, 0], IDENTITY_QUAT, [1, 1, 1]);
  assert.deepEqual(I, [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
  for (let n = 0; n < 50; n++) {
    const a = randomTransform(true), b = randomTransform(true), m = trs(a.t, a.q, a.s);
    close(mat4Multiply(m, I), m, 0);
    close(mat4Multiply(I, m), m, 0);
    const ab = composeTransforms(a, b);
    close(mat4Multiply(m, trs(b.t, b.q, b.s)), trs(ab.t, ab.q, ab.s), 1e-12);
    // The composed transform's inverse (unapply) undoes the product's map.
    const x = randomVector();
    close(unapplyTransform(b, unapplyTransform(a, transformPoint(mat4Multiply(m, trs(b.t, b.q, b.s)), x))), x, 1e-11);
  }
});

test("eulerDegrees: single-axis rotations in every order", () => {
  for (const order of ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]) {
    close(eulerDegrees(axisAngle(X, 30), order), [30, 0, 0], 1e-12, order);
    close(eulerDegrees(axisAngle(Y, -45), order), [0, -45, 0], 1e-12, order);
    close(eulerDegrees(axisAngle(Z, 60), order), [0, 0, 60], 1e-12, order);
    close(eulerDegrees([0, 0, 0, 2], order), [0, 0, 0], 0, "normalised first");
  }
});

test("eulerDegrees: the angles rebuild the rotation in their order", () => {
  const axes = { X, Y, Z };
  for (const order of ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]) {
    for (let n = 0; n < 30; n++) {
      const q = randomQuat();
      const angles = eulerDegrees(q, order);
      // `order[0]` applied first: q = q_last · q_middle · q_first.
      const rebuilt = [...order].reduce((acc, axis) => qmul(axisAngle(axes[axis], angles["XYZ".indexOf(axis)]), acc), IDENTITY_QUAT);
      const v = randomVector();
      close(rotate(rebuilt, v), rotate(q, v), 1e-9, order);
    }
  }
});

test("nearestBranch, unwrapSeries and nearestIndex", () => {
  assert.deepEqual(nearestBranch([170, -170, 10], [-175, 175, 10]), [-190, 190, 10]);
  assert.deepEqual(unwrapSeries([[170], [-170], [-150], [175]]), [[170], [190], [210], [175]]);
  assert.deepEqual(unwrapSeries([]), []);
  assert.equal(nearestIndex([0, 1, 2, 3], 1.4), 1);
  assert.equal(nearestIndex([0, 1, 2, 3], 1.5), 1, "the first of equals");
  assert.equal(nearestIndex([0, 1, 2, 3], 9), 3);
});

test("eases: endpoints, the midpoint, and unease inverts each", () => {
  for (const [name, ease] of Object.entries(EASES)) {
    assert.equal(ease(0), 0, name);
    assert.equal(ease(1), 1, name);
    for (const x of [0.1, 0.25, 0.5, 0.8]) assert.ok(Math.abs(unease(ease, ease(x)) - x) < 1e-11, `${name} ${x}`);
    // At a flat end (x² at 0, 1 - (1-x)² at 1) the inverse is only as good as √ε.
    for (const x of [0, 1]) assert.ok(Math.abs(unease(ease, ease(x)) - x) < 1e-7, `${name} ${x}`);
  }
  assert.equal(EASES.ease_in(0.5), 0.25);
  assert.equal(EASES.ease_out(0.5), 0.75);
  assert.equal(EASES.ease_in_out(0.5), 0.5);
});

test("cameraBasis: orthonormal axes, the target at the centre, the eye at the distance", () => {
  const orbit = { yaw: 0.7, pitch: 0.35, dist: 5, target: [0, 1, 0] };
  const cam = cameraBasis(orbit, 800, 480);
  for (const [a, b] of [[cam.f, cam.r], [cam.f, cam.u], [cam.r, cam.u]]) assert.ok(Math.abs(dot(a, b)) < 1e-15);
  for (const a of [cam.f, cam.r, cam.u]) assert.ok(Math.abs(Math.hypot(...a) - 1) < 1e-15);
  assert.ok(Math.abs(Math.hypot(...sub(cam.eye, orbit.target)) - 5) < 1e-14);
  assert.ok(cam.u[1] > 0, "up is up");
  close(toCamera(cam, orbit.target), [0, 0, 5], 1e-14);
  close(toScreen(cam, toCamera(cam, orbit.target)), [400, 240], 1e-12);
  // 45° vertical field: a point at the top edge of the view at the target's depth.
  const top = [0, 1, 2].map((k) => orbit.target[k] + Math.tan(Math.PI / 8) * 5 * cam.u[k]);
  close(toScreen(cam, toCamera(cam, top)), [400, 0], 1e-9);
  // Looking straight down -z from +z (yaw 0, pitch 0): right is +x.
  const front = cameraBasis({ yaw: 0, pitch: 0, dist: 2, target: [0, 0, 0] }, 100, 100);
  close(front.eye, [0, 0, 2], 1e-15);
  close(front.r, [1, 0, 0], 1e-15);
});

test("viewProjection: the same screen point as toScreen, depth within the range", () => {
  const orbit = { yaw: -1.2, pitch: 0.5, dist: 3, target: [0.5, 1, -0.2], radius: 1 };
  const cam = cameraBasis(orbit, 640, 360);
  const m = viewProjection(cam, orbit, 640, 360);
  for (let n = 0; n < 20; n++) {
    const p = randomVector(0.8).map((c, k) => c + orbit.target[k]);
    const clip = [0, 1, 2, 3].map((r) => m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r]);
    const ndc = clip.slice(0, 3).map((c) => c / clip[3]);
    const [sx, sy] = toScreen(cam, toCamera(cam, p));
    close([((ndc[0] + 1) / 2) * 640, ((1 - ndc[1]) / 2) * 360], [sx, sy], 1e-3);
    assert.ok(ndc[2] > -1 && ndc[2] < 1, `depth ${ndc[2]}`);
  }
});
