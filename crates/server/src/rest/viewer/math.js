// The viewer's maths, in one place and free of the page (no DOM, no state),
// so that `node --test` checks it (tests/math.test.js beside this file).
//
// Conventions: vectors are `[x, y, z]`; quaternions `[x, y, z, w]` (as the
// API sends them); a transform is `{ t, q, s }` (translation, rotation,
// per-axis scale, applied scale first, then rotation, then translation);
// 4×4 matrices are flat arrays of 16, column-major (as WebGL takes them).

// ---- vectors ----

export const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
export const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
export const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];

/// `a` scaled to length 1 (a zero vector stays zero).
export const normalize = (a) => {
  const n = Math.hypot(a[0], a[1], a[2]) || 1;
  return [a[0] / n, a[1] / n, a[2] / n];
};

// ---- quaternions ----

export const IDENTITY_QUAT = Object.freeze([0, 0, 0, 1]);

/// The product `a·b`: rotating by `b`, then by `a`.
export function qmul(a, b) {
  const [ax, ay, az, aw] = a, [bx, by, bz, bw] = b;
  return [
    aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw,
    aw * bw - ax * bx - ay * by - az * bz,
  ];
}

/// The conjugate: the inverse rotation of a unit quaternion.
export const conj = (q) => [-q[0], -q[1], -q[2], q[3]];

/// `v` rotated by the unit quaternion `q`: v + 2w(q×v) + 2q×(q×v).
export function rotate(q, v) {
  const [x, y, z, w] = q;
  const cx = y * v[2] - z * v[1], cy = z * v[0] - x * v[2], cz = x * v[1] - y * v[0];
  const dx = y * cz - z * cy, dy = z * cx - x * cz, dz = x * cy - y * cx;
  return [v[0] + 2 * (w * cx + dx), v[1] + 2 * (w * cy + dy), v[2] + 2 * (w * cz + dz)];
}

/// The angle about +y of a rotation about +y (the heading of a root).
export const yawOf = (q) => 2 * Math.atan2(q[1], q[3]);

/// `v` turned by `yaw` radians about +y.
export const turn = (yaw, v) => [Math.cos(yaw) * v[0] + Math.sin(yaw) * v[2], v[1], -Math.sin(yaw) * v[0] + Math.cos(yaw) * v[2]];

// ---- transforms { t, q, s } ----

export const IDENTITY = Object.freeze({ t: [0, 0, 0], q: [0, 0, 0, 1], s: [1, 1, 1] });

/// A point of `f`'s space in its parent's: t + q·(s∘x).
export const applyTransform = (f, x) => rotate(f.q, x.map((c, k) => c * f.s[k])).map((c, k) => c + f.t[k]);

/// The inverse of `applyTransform` (a zero scale taken as 1).
export const unapplyTransform = (f, p) => rotate(conj(f.q), p.map((c, k) => c - f.t[k])).map((c, k) => c / (f.s[k] || 1));

/// `local` (a child's transform) placed under `parent`: scales taken per
/// axis, unsheared, as the server composes them.
export const composeTransforms = (parent, local) => ({
  t: applyTransform(parent, local.t),
  q: qmul(parent.q, local.q),
  s: parent.s.map((c, k) => c * local.s[k]),
});

/// The model transforms of a pose's joints from their local ones, given
/// each joint's parent index (-1 for a root). A joint whose parent does not
/// come before it is taken as a root.
export function modelTransforms(locals, parents) {
  const model = [];
  locals.forEach((local, i) => {
    const p = parents[i];
    model.push(p < 0 || p >= i ? local : composeTransforms(model[p], local));
  });
  return model;
}

// ---- 4×4 matrices (column-major) ----

/// The matrix of translation t, rotation q = [x, y, z, w], scale s.
export function trs(t, q, s) {
  const [x, y, z, w] = q;
  const m = [
    1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w), 0,
    2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w), 0,
    2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y), 0,
    t[0], t[1], t[2], 1,
  ];
  for (let c = 0; c < 3; c++) for (let r = 0; r < 3; r++) m[4 * c + r] *= s[c];
  return m;
}

/// The product `a·b`.
export function mat4Multiply(a, b) {
  const out = new Array(16);
  for (let c = 0; c < 4; c++)
    for (let r = 0; r < 4; r++)
      out[4 * c + r] = a[r] * b[4 * c] + a[4 + r] * b[4 * c + 1] + a[8 + r] * b[4 * c + 2] + a[12 + r] * b[4 * c + 3];
  return out;
}

// ---- Euler angles ----

/// Euler angles in degrees, `[x, y, z]`, of the unit quaternion `[x, y, z,
/// w]` for `order` ("XYZ": X applied first, R = Rz·Ry·Rx).
export function eulerDegrees(q, order) {
  const [x, y, z, w] = q;
  const n = Math.hypot(x, y, z, w) || 1;
  const [qx, qy, qz, qw] = [x / n, y / n, z / n, w / n];
  const R = [
    [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
    [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
    [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
  ];
  const [i, j, k] = [...order].map((c) => "XYZ".indexOf(c));
  const s = (j - i + 3) % 3 === 1 ? 1 : -1; // +1 for the cyclic orders
  const out = [0, 0, 0];
  out[i] = Math.atan2(s * R[k][j], R[k][k]);
  out[j] = Math.asin(Math.max(-1, Math.min(1, -s * R[k][i])));
  out[k] = Math.atan2(s * R[j][i], R[i][i]);
  return out.map((r) => (r * 180) / Math.PI);
}

/// `a` with whole turns added to each angle (degrees) to be nearest `b`.
export const nearestBranch = (a, b) => a.map((v, c) => v + 360 * Math.round((b[c] - v) / 360));

/// Angles made continuous along the series (no ±180° jumps).
export function unwrapSeries(series) {
  const out = [];
  for (const v of series) out.push(out.length ? nearestBranch(v, out[out.length - 1]) : v);
  return out;
}

/// The index of the time in `times` nearest `t` (the first of equals).
export function nearestIndex(times, t) {
  let best = 0;
  times.forEach((x, i) => Math.abs(x - t) < Math.abs(times[best] - t) && (best = i));
  return best;
}

// ---- eases: request time → clip time, and back ----

export const EASES = {
  linear: (x) => x,
  ease_in: (x) => x * x,
  ease_out: (x) => 1 - (1 - x) * (1 - x),
  ease_in_out: (x) => 3 * x * x - 2 * x * x * x,
};

/// The `x` in [0, 1] whose `ease(x)` is `y` (each ease is increasing, so
/// bisection finds it; 40 halvings).
export function unease(ease, y) {
  let lo = 0, hi = 1;
  for (let i = 0; i < 40; i++) {
    const mid = (lo + hi) / 2;
    if (ease(mid) < y) lo = mid;
    else hi = mid;
  }
  return (lo + hi) / 2;
}

// ---- the orbit camera ----

/// The camera of an orbit `{ yaw, pitch, dist, target }` (45° vertical field
/// of view) for a view `width`×`height` pixels: its eye, forward `f`, right
/// `r` and up `u` axes, focal length and centre in pixels, near distance.
export function cameraBasis({ yaw, pitch, dist, target }, width, height) {
  const eye = [
    target[0] + dist * Math.cos(pitch) * Math.sin(yaw),
    target[1] + dist * Math.sin(pitch),
    target[2] + dist * Math.cos(pitch) * Math.cos(yaw),
  ];
  const f = normalize(sub(target, eye));
  const r = normalize(cross(f, [0, 1, 0]));
  const u = cross(r, f);
  const focal = height / (2 * Math.tan((45 * Math.PI) / 360));
  const near = dist * 1e-3;
  return { eye, f, r, u, focal, near, cx: width / 2, cy: height / 2 };
}

/// A world point in the camera's axes: `[right, up, depth]`.
export const toCamera = (cam, p) => {
  const d = sub(p, cam.eye);
  return [dot(d, cam.r), dot(d, cam.u), dot(d, cam.f)];
};

/// A camera-space point (in front of the camera) on the screen, in pixels, y down.
export const toScreen = (cam, v) => [cam.cx + (v[0] / v[2]) * cam.focal, cam.cy - (v[1] / v[2]) * cam.focal];

/// `cameraBasis`'s projection as one column-major matrix (to clip space),
/// with a depth range around an orbit at `dist` framing a size `radius`.
export function viewProjection(cam, { dist, radius }, width, height) {
  const near = Math.max(cam.near, dist * 0.01), far = dist + 40 * radius;
  const a = (far + near) / (far - near), b = (-2 * far * near) / (far - near);
  const sx = (2 * cam.focal) / width, sy = (2 * cam.focal) / height;
  const row = (axis) => [axis[0], axis[1], axis[2], -(axis[0] * cam.eye[0] + axis[1] * cam.eye[1] + axis[2] * cam.eye[2])];
  const [r, u, f] = [row(cam.r), row(cam.u), row(cam.f)];
  const rows = [r.map((x) => sx * x), u.map((x) => sy * x), f.map((x, i) => a * x + (i === 3 ? b : 0)), f];
  const m = new Float32Array(16);
  for (let c = 0; c < 4; c++) for (let k = 0; k < 4; k++) m[4 * c + k] = rows[k][c];
  return m;
}
