// The 3D view: an orbit camera around the clip, the ground, and the
// skeleton as solids on the 2D canvas (a small hand-written projection, no
// library); with a skinned mesh, mesh.js draws ground and mesh on a WebGL
// canvas below and this one only the skeleton.

import { postJson } from "./api.js";
import { $, COLORS, setStatus, sizeCanvas, stroke } from "./dom.js";
import { emit, on } from "./events.js";
import { cameraBasis, cross, dot, normalize, sub, toCamera, toScreen } from "./math.js";
import * as mesh from "./mesh.js";
import { draw } from "./render.js";
import { state } from "./state.js";

const FIT_POINTS = 30; // model-space poses sampled to fit the camera
const BONE_RGB = [200, 208, 220];
const JOINT_COLOR = "#ff8c1a";
const SELECTED_COLOR = "#3ee0ff";

/// What the last frame drew of the skeleton (read by the browser test).
let drawn = null;
export const drawnSkeleton = () => drawn;

/// Draws the scene at the next animation frame (once, however often asked; render.js).
export const requestDraw = () => draw("scene", drawScene);

/// The scene's camera now, in the scene canvas's pixels.
export function sceneCamera() {
  const canvas = $("scene");
  return { ...cameraBasis(state.camera, canvas.width, canvas.height), dpr: window.devicePixelRatio || 1 };
}

/// A world-space segment, clipped at the near plane.
function line(ctx, cam, a, b) {
  let p = toCamera(cam, a), q = toCamera(cam, b);
  if (p[2] < cam.near && q[2] < cam.near) return;
  if (p[2] < cam.near || q[2] < cam.near) {
    const k = (cam.near - p[2]) / (q[2] - p[2]);
    const cut = [p[0] + k * (q[0] - p[0]), p[1] + k * (q[1] - p[1]), cam.near];
    if (p[2] < cam.near) p = cut;
    else q = cut;
  }
  const [x0, y0] = toScreen(cam, p), [x1, y1] = toScreen(cam, q);
  ctx.moveTo(x0, y0);
  ctx.lineTo(x1, y1);
}

/// The floor grid and the axes at the origin, as world-space segments by
/// colour (RGBA 0–1 for mesh.js's WebGL, the CSS colour for the canvas).
function groundLines() {
  const { target, radius } = state.camera;
  const step = 10 ** Math.floor(Math.log10(radius)) / 2;
  const n = Math.ceil((2 * radius) / step);
  const ox = Math.round(target[0] / step) * step, oz = Math.round(target[2] / step) * step;
  const grid = [];
  for (let i = -n; i <= n; i++) {
    grid.push([[ox + i * step, 0, oz - n * step], [ox + i * step, 0, oz + n * step]]);
    grid.push([[ox - n * step, 0, oz + i * step], [ox + n * step, 0, oz + i * step]]);
  }
  const rgba = (css) => [1, 3, 5].map((k) => parseInt(css.slice(k, k + 2), 16) / 255).concat(1);
  const axis = 2 * step;
  const axes = [[axis, 0, 0], [0, axis, 0], [0, 0, axis]].map((end, i) => ({
    css: COLORS[i], color: rgba(COLORS[i]), width: 2, segments: [[[0, 0, 0], end]],
  }));
  return [{ css: "#323846", color: rgba("#323846"), width: 1, segments: grid }, ...axes];
}

function drawScene() {
  follow();
  const canvas = $("scene");
  const dpr = sizeCanvas(canvas);
  const ctx = canvas.getContext("2d");
  const cam = cameraBasis(state.camera, canvas.width, canvas.height);
  const lines = groundLines();
  // With a skinned mesh, mesh.js draws background, ground and mesh below; this canvas only the skeleton.
  const withMesh = mesh.draw(cam, canvas.width, canvas.height, lines);
  if (withMesh) ctx.clearRect(0, 0, canvas.width, canvas.height);
  else {
    ctx.fillStyle = "#101216";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    for (const { css, width, segments } of lines)
      stroke(ctx, css, width * dpr, () => segments.forEach(([a, b]) => line(ctx, cam, a, b)));
  }
  if (!withMesh || mesh.mesh.showSkeleton) drawSkeleton(ctx, cam);
  else drawn = { bones: [], joints: 0 };
  drawSelection(ctx, cam, dpr);
  emit("overlay", ctx, cam, dpr);
}

// ---- the skeleton as solids: octahedral bones and shaded joint spheres,
// drawn far to near (painter's algorithm) on the 2D canvas ----

/// The bones and joints to draw this frame, and their world sizes: the
/// sphere radius and bone width follow the median bone length, bounded by
/// the framed size so that neither vanishes nor swamps the view.
function skeletonItems() {
  const pos = state.positions, drawnJoints = state.drawnJoints || [];
  const bones = [];
  state.parents.forEach((p, i) => {
    if (p >= 0 && drawnJoints[p] && drawnJoints[i] && pos[p] && pos[i]) bones.push([p, i]);
  });
  const lengths = bones.map(([p, i]) => Math.hypot(...sub(pos[i], pos[p]))).filter((l) => l > 0).sort((a, b) => a - b);
  const median = lengths.length ? lengths[lengths.length >> 1] : state.camera.radius * 0.2;
  const R = state.camera.radius;
  const radius = Math.min(0.04 * R, Math.max(0.008 * R, 0.12 * median));
  const joints = pos.map((_, i) => i).filter((i) => drawnJoints[i] && pos[i]);
  return { pos, bones, joints, radius };
}

/// The 8 faces of an octahedral bone from `a` to `b`: a square ring a fifth
/// of the way along, pointed at both ends.
function boneFaces(a, b, width) {
  const d = sub(b, a);
  const len = Math.hypot(...d);
  if (len < 1e-9) return [];
  const axis = [d[0] / len, d[1] / len, d[2] / len];
  const helper = Math.abs(axis[1]) < 0.9 ? [0, 1, 0] : [1, 0, 0];
  const u = normalize(cross(axis, helper)), v = cross(axis, u);
  const w = Math.min(width, 0.15 * len);
  const c = [a[0] + 0.2 * d[0], a[1] + 0.2 * d[1], a[2] + 0.2 * d[2]];
  const ring = [u, v, u.map((x) => -x), v.map((x) => -x)].map((e) => [c[0] + w * e[0], c[1] + w * e[1], c[2] + w * e[2]]);
  const faces = [];
  for (let k = 0; k < 4; k++) {
    const r0 = ring[k], r1 = ring[(k + 1) % 4];
    faces.push([a, r1, r0], [b, r0, r1]);
  }
  return faces;
}

/// How far behind the mesh's nearest surface, in sphere radii, a part of
/// the skeleton is on the far side of the body (all bones are inside the
/// mesh; those just under the near surface stay bright).
const BEHIND_RADII = 3;
/// The opacity of the parts behind the mesh.
const DIMMED = 0.25;

function drawSkeleton(ctx, cam) {
  const { pos, bones, joints, radius } = skeletonItems();
  const light = normalize([cam.u[0] * 0.6 - cam.r[0] * 0.4 - cam.f[0], cam.u[1] * 0.6 - cam.r[1] * 0.4 - cam.f[1], cam.u[2] * 0.6 - cam.r[2] * 0.4 - cam.f[2]]);
  const items = [];
  for (const [p, i] of bones)
    for (const face of boneFaces(pos[p], pos[i], 1.6 * radius)) {
      const n = normalize(cross(sub(face[1], face[0]), sub(face[2], face[0])));
      if (dot(n, sub(face[0], cam.eye)) >= 0) continue; // facing away
      const v = face.map((q) => toCamera(cam, q));
      if (v.some((q) => q[2] < cam.near)) continue;
      const shade = 0.35 + 0.65 * Math.max(0, dot(n, light));
      items.push({ depth: (v[0][2] + v[1][2] + v[2][2]) / 3, face: v.map((q) => toScreen(cam, q)), shade });
    }
  for (const i of joints) {
    const v = toCamera(cam, pos[i]);
    if (v[2] < cam.near * 2) continue;
    items.push({ depth: v[2] - radius, center: toScreen(cam, v), r: (radius * cam.focal) / v[2] });
  }
  items.sort((a, b) => b.depth - a.depth);
  let dimmed = 0;
  for (const item of items) {
    const behind = behindMesh(item, BEHIND_RADII * radius);
    dimmed += behind;
    ctx.globalAlpha = behind ? DIMMED : 1;
    (item.face ? drawFace : drawSphere)(ctx, item);
  }
  ctx.globalAlpha = 1;
  drawn = { bones: bones.map(([p, i]) => [state.names[p], state.names[i]]), joints: joints.length, items: items.length, dimmed };
}

/// Whether a face or joint lies more than `margin` behind the mesh's near surface where it is drawn.
function behindMesh(item, margin) {
  const at = item.center || [(item.face[0][0] + item.face[1][0] + item.face[2][0]) / 3, (item.face[0][1] + item.face[1][1] + item.face[2][1]) / 3];
  const surface = mesh.meshDistanceAt(at);
  return surface != null && item.depth - surface > margin;
}

/// The selected joint: a cyan ring around it, drawn over everything.
function drawSelection(ctx, cam, dpr) {
  const i = state.names.indexOf(state.selectedJoint);
  if (i < 0 || !state.positions[i]) return;
  const v = toCamera(cam, state.positions[i]);
  if (v[2] <= cam.near) return;
  const [x, y] = toScreen(cam, v);
  ctx.beginPath();
  ctx.arc(x, y, 9 * dpr, 0, 2 * Math.PI);
  ctx.strokeStyle = SELECTED_COLOR;
  ctx.lineWidth = 2.5 * dpr;
  ctx.stroke();
}

function drawFace(ctx, { face, shade }) {
  ctx.beginPath();
  ctx.moveTo(face[0][0], face[0][1]);
  ctx.lineTo(face[1][0], face[1][1]);
  ctx.lineTo(face[2][0], face[2][1]);
  ctx.closePath();
  const [r, g, b] = BONE_RGB.map((c) => Math.round(c * shade));
  ctx.fillStyle = `rgb(${r},${g},${b})`;
  ctx.strokeStyle = ctx.fillStyle; // closes the hairline seams between faces
  ctx.lineWidth = 0.5;
  ctx.fill();
  ctx.stroke();
}

/// A lit sphere: a radial gradient with its highlight up and to the left.
function drawSphere(ctx, { center: [x, y], r }) {
  const g = ctx.createRadialGradient(x - 0.35 * r, y - 0.35 * r, 0.1 * r, x, y, r);
  g.addColorStop(0, "#ffd0a0");
  g.addColorStop(0.45, JOINT_COLOR);
  g.addColorStop(1, "#a04f00");
  ctx.fillStyle = g;
  ctx.beginPath();
  ctx.arc(x, y, Math.max(r, 1.5), 0, 2 * Math.PI);
  ctx.fill();
}

/// The bounds of a set of points: their centre and half-diagonal.
export function bounds(points) {
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (const p of points)
    for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], p[k]);
      hi[k] = Math.max(hi[k], p[k]);
    }
  if (!(lo[0] <= hi[0])) return null;
  return { center: lo.map((l, k) => (l + hi[k]) / 2), radius: Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2 };
}

/// The orbit distance at which a sphere of `radius` about the target
/// fills nine tenths of the view's height (45° field of view).
export const fitDistance = (radius) => radius / (0.9 * Math.tan((22.5 * Math.PI) / 180));

/// The figure's size (the largest of its poses' own bounds over the range)
/// and where it stands at the start.
let figure = null;

/// How far a take may travel, against the figure's size, and still be
/// framed whole; one that goes further is framed on the figure, which the
/// camera then follows.
const FRAME_TRAVEL = 1.5;

/// Frames the clip: the whole of its path when it stays near, else the
/// figure (a BVH walk fills most of the view's height) with the camera
/// following it.
export async function fitCamera() {
  const { id, start, end } = state.clip;
  const fps = end > start ? Math.min(240, Math.max(1, FIT_POINTS / (end - start))) : 1;
  const range = { start, end, fps, space: "model" };
  // On a character, the clip's poses retargeted onto it (its size, not the clip's).
  const { poses } = state.character
    ? await postJson("/v1/samples", { motion: { layers: [{ clip: id, playback: "once" }], character: state.character.id }, ...range })
    : await postJson(`/v1/clips/${encodeURIComponent(id)}/sample`, { ...range, playback: "once" });
  const each = poses.map((pose) => bounds(pose.joints.map((j) => j.translation))).filter(Boolean);
  const travel = bounds(poses.flatMap((pose) => pose.joints.map((j) => j.translation)));
  if (!each.length || !travel) return;
  figure = { center: each[0].center, radius: Math.max(...each.map((b) => b.radius), 1e-3) };
  const near = travel.radius <= FRAME_TRAVEL * figure.radius;
  const framed = near ? travel : figure;
  frame(framed.center, framed.radius);
  state.camera.radius = framed.radius;
  state.camera.follow = !near;
}

/// A following camera keeps the figure's centre (as posed now) in view, at the framed height.
function follow() {
  const cam = state.camera;
  if (!cam.follow) return;
  const b = bounds(state.positions.filter(Boolean));
  if (b) cam.target = [b.center[0], cam.target[1], b.center[2]];
}

/// Points the camera at `center`, far enough to see a sphere of `radius` whole.
function frame(center, radius) {
  const cam = state.camera;
  cam.target = [...center];
  cam.dist = fitDistance(radius);
  cam.follow = false;
  requestDraw();
}

/// Frames the selected joint with what hangs from it (its subtree), no
/// smaller than a third of the figure, as it is posed now.
export function frameSelection() {
  const i = state.names.indexOf(state.selectedJoint);
  if (i < 0 || !state.positions[i]) return;
  const inside = state.names.map((_, j) => {
    for (let k = j; k >= 0; k = state.parents[k]) if (k === i) return true;
    return false;
  });
  const b = bounds(state.positions.filter((p, j) => inside[j] && p));
  frame(state.positions[i], Math.max(b ? b.radius + Math.hypot(...sub(b.center, state.positions[i])) : 0, (figure?.radius ?? state.camera.radius) / 3));
}

// ---- picking: a click on a joint (or on the mesh near it) selects it ----

/// The drawn joint nearest to screen point `at` (canvas pixels) within
/// `reach` pixels, by its screen position; null if none is that near.
export function nearestJoint(cam, at, reach) {
  let best = null;
  state.positions.forEach((p, i) => {
    if (!p || !state.drawnJoints[i]) return;
    const v = toCamera(cam, p);
    if (v[2] <= cam.near) return;
    const [x, y] = toScreen(cam, v);
    const d = Math.hypot(x - at[0], y - at[1]);
    if (d <= reach && (!best || d < best.distance)) best = { index: i, name: state.names[i], distance: d };
  });
  return best;
}

/// How far from a joint a click still picks it (CSS pixels): on the bare
/// skeleton, a joint's sphere and a little; on a mesh, the part of the body around it.
const PICK_PX = 14, PICK_MESH_PX = 40;

function pick(e) {
  const canvas = $("scene");
  const cam = sceneCamera();
  const r = canvas.getBoundingClientRect();
  const at = [(e.clientX - r.left) * cam.dpr, (e.clientY - r.top) * cam.dpr];
  const onMesh = mesh.mesh.clip && mesh.mesh.showMesh;
  const hit = nearestJoint(cam, at, (onMesh ? PICK_MESH_PX : PICK_PX) * cam.dpr);
  selectJoint(hit ? hit.name : null);
}

/// Selects joint `name` (null: none): the view frames it and marks it; the page is told (`jointSelected`).
export function selectJoint(name) {
  state.selectedJoint = name;
  if (name) frameSelection();
  emit("jointSelected", name);
  requestDraw();
}

/// Dragging orbits, the wheel zooms, a double click frames the clip again.
function setupOrbit() {
  const canvas = $("scene");
  let drag = null;
  let press = null; // where a press began: a press that does not move is a click, which picks
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY };
    press = { x: e.clientX, y: e.clientY };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const cam = state.camera;
    cam.yaw -= (e.clientX - drag.x) * 0.01;
    cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + (e.clientY - drag.y) * 0.01));
    drag = { x: e.clientX, y: e.clientY };
    requestDraw();
  });
  canvas.addEventListener("pointerup", (e) => {
    drag = null;
    if (press && Math.hypot(e.clientX - press.x, e.clientY - press.y) < 4 && state.clip) pick(e);
    press = null;
  });
  canvas.addEventListener(
    "wheel",
    (e) => {
      e.preventDefault();
      state.camera.dist *= Math.exp(e.deltaY * 0.001);
      requestDraw();
    },
    { passive: false },
  );
  canvas.addEventListener("dblclick", () => state.clip && fitCamera());
  document.addEventListener("keydown", (e) => {
    const t = e.target;
    if (e.key !== "f" || e.ctrlKey || e.metaKey || e.altKey || (t instanceof HTMLElement && t.closest("input, select, textarea"))) return;
    if (state.selectedJoint) frameSelection();
    else if (state.clip) fitCamera();
  });
}

export function setup() {
  on("redraw", requestDraw);
  on("clipSelected", () => (state.selectedJoint = null));
  on("characterChanged", () => {
    state.selectedJoint = null;
    if (state.clip) fitCamera().catch((e) => setStatus(`framing the character: ${e.message}`, true));
  });
  setupOrbit();
}
