// The viewer's composition and IK panel (issue 20). The page plays a
// *motion* (docs/motion.md; composition.js holds it) over `GET /v1/stream` with an
// `open` message: the selected clip is its first layer, more layers come
// from the clip list, each with a weight slider (live `layer` controls) and
// a mask (a joint and its descendants); a button crossfades to another clip
// (a live `crossfade` control); root motion is drawn as a trail on the
// ground, with `extract` on or off. IK handles (docs/ik.md; two-bone or aim on
// a chosen joint) are dragged in the 3D view's camera plane and sent as live
// `ik` controls, at most once a frame.

import { choose } from "./character.js";
import { adoptClip, selectClip } from "./clips.js";
import { constraint, layerDoc, motion, panel, resetTrail } from "./composition.js";
import { send } from "./controls.js";
import { $, COLORS, el, row, setStatus } from "./dom.js";
import { on } from "./events.js";
import { IDENTITY, applyTransform, composeTransforms, conj, qmul, toCamera, toScreen, turn, unapplyTransform, yawOf } from "./math.js";
import { reopen, showPoseAt } from "./player.js";
import { requestDraw, sceneCamera } from "./scene.js";
import { fps, options } from "./settings.js";
import { shownSkeleton, state } from "./state.js";

const HANDLE_PX = 9; // the handle's radius on screen, CSS pixels
const GRAB_PX = 16; // how near a press must be to grab it
const TRAIL_POINTS = 900; // root-motion trail length, at most
const HANDLE_COLOR = "#3ad1e6";
const GIZMO_PX = 60; // the gizmo's arrows' length at the handle's depth, CSS pixels
const AXIS_GRAB_PX = 8; // how near a press must be to an arrow of the translate gizmo to grab it
const AXES = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
const TRAIL_COLOR = "#ff8c1a";

// ---- the DOM ----

/// The class of the controls only clip layers have (a graph is the motion's
/// only layer, so panel.css hides them while one plays).
const layersOnly = (element) => (element.classList.add("layers-only"), element);

function build() {
  const composition = el(
    "section",
    { id: "composition" },
    el("h2", { textContent: "Composition" }),
    layersOnly(el("ol", { id: "layers", ariaLabel: "Layers" })),
    layersOnly(row(el("select", { id: "layer-clip", ariaLabel: "Clip to add as a layer" }), el("button", { id: "layer-add", type: "button", textContent: "Add layer" }))),
    layersOnly(row(
      el("select", { id: "fade-clip", ariaLabel: "Clip to crossfade to" }),
      el("input", { id: "fade-duration", type: "number", min: "0", max: "60", step: "0.1", value: "0.5", ariaLabel: "Crossfade seconds" }),
      el("button", { id: "fade", type: "button", textContent: "Crossfade" }),
    )),
    row(
      el("label", {}, "root ", el("select", { id: "root-mode" }, new Option("off", ""), new Option("trail", "report"), new Option("trail, extract", "extract"))),
      el("select", { id: "root-joint", ariaLabel: "Root-motion joint" }),
    ),
    el("p", { id: "playing", className: "info" }),
  );
  const ik = el(
    "section",
    { id: "ik-panel" },
    el("h2", { textContent: "IK" }),
    row(
      el("select", { id: "ik-joint", ariaLabel: "IK joint" }),
      el("select", { id: "ik-kind", ariaLabel: "IK preset" }, new Option("two-bone", "two_bone"), new Option("aim", "aim")),
    ),
    row(el("button", { id: "ik-add", type: "button", textContent: "Add handle" }), el("button", { id: "ik-remove", type: "button", textContent: "Remove", disabled: true })),
    el("p", { id: "ik-info", className: "info", textContent: "drag the handle in the view" }),
  );
  $("panel").append(composition, ik);
}

// ---- the motion ----

/// Shows a change: a running stream restarts with it (from the time shown),
/// a broadcast crossfades to it, a paused view fetches its pose.
function recompose() {
  renderLayers();
  if (state.watching) return crossfadeTo(motion({ ik: false }), fadeSeconds());
  reopen();
}

function crossfadeTo(to, duration) {
  send({ op: "crossfade", to, duration, ease: "ease_in_out" });
}

const fadeSeconds = () => Math.max(0, Number($("fade-duration").value) || 0);
const report = (e) => setStatus(e.message, true);
/// The paused view's pose again, at most once a frame.
const refreshThrottled = throttled(() => showPoseAt(state.requestTime).catch(report));
/// What the page calls clip (or graph) `id`.
const clipName = (id) => (id === state.graph?.id ? `graph ${state.graph.name}` : state.clips.find((c) => c.id === id)?.name ?? id);

// ---- layers ----

function renderLayers() {
  const joints = jointNames();
  const items = panel.layers.map((layer, i) => {
    const weight = el("input", { type: "range", min: "0", max: "1", step: "0.01", value: String(layer.weight), ariaLabel: `Layer ${i} weight` });
    const shown = el("span", { className: "weight", textContent: layer.weight.toFixed(2) });
    weight.addEventListener("input", () => {
      layer.weight = Number(weight.value);
      shown.textContent = layer.weight.toFixed(2);
      sendWeight(i);
    });
    const mask = el("select", { ariaLabel: `Layer ${i} mask` }, new Option("all joints", ""), ...joints.map((j) => new Option(`${j} ↓`, j)));
    mask.value = layer.mask || "";
    mask.addEventListener("change", () => {
      layer.mask = mask.value || null;
      recompose();
    });
    const remove = el("button", { type: "button", textContent: "×", title: "Remove this layer", disabled: i === 0 });
    remove.addEventListener("click", () => {
      panel.layers.splice(i, 1);
      recompose();
    });
    const item = el("li", {}, row(el("span", { className: "name", textContent: clipName(layer.clip) }), remove), row(weight, shown, mask));
    item.dataset.index = String(i);
    return item;
  });
  $("layers").replaceChildren(...items);
}

/// A weight slider's value as a live `layer` control, at most once a frame.
const weightSenders = [];
function sendWeight(index) {
  if (!state.ws) return refreshThrottled();
  weightSenders[index] ??= throttled(() => send({ op: "layer", index, weight: panel.layers[index].weight, duration: 0 }));
  weightSenders[index]();
}

/// `f` called at most once per frame of the stream, the last call always made.
function throttled(f) {
  let last = 0, timer = null;
  return () => {
    const period = 1000 / fps();
    const wait = last + period - performance.now();
    if (timer) return;
    if (wait <= 0) {
      last = performance.now();
      return f();
    }
    timer = setTimeout(() => {
      timer = null;
      last = performance.now();
      f();
    }, wait);
  };
}

function fillClipSelect(select) {
  const value = select.value;
  select.replaceChildren(...state.clips.map((c) => new Option(c.name, c.id)));
  if (value) select.value = value;
}

/// The joints of the skeleton the poses are on: the character's, else the
/// clip's (a graph's clip is its output skeleton's, graph.js).
const skeletonJoints = () => shownSkeleton()?.joints || [];
const jointNames = () => skeletonJoints().map((j) => j.name);

/// Joints a root motion can follow: those with a translation track, roots
/// first; on a character, its hips (the only joint a retarget moves), else its roots.
function rootCandidates() {
  if (state.character) {
    const hips = state.characters.find((c) => c.id === state.character.id)?.roles?.hips?.joint;
    return hips ? [hips] : skeletonJoints().filter((j) => j.parent == null).map((j) => j.name);
  }
  const moving = new Set((state.doc?.tracks || []).filter((t) => t.channel === "translation").map((t) => t.joint));
  const joints = skeletonJoints().filter((j) => moving.has(j.name));
  return [...joints.filter((j) => j.parent == null), ...joints.filter((j) => j.parent != null)].map((j) => j.name);
}

/// The root and IK joint selects, from the skeleton the poses are on; the
/// root joint and the handle are kept where that skeleton has their joints.
function fillJointSelects() {
  const roots = rootCandidates(), names = jointNames();
  $("root-joint").replaceChildren(...roots.map((j) => new Option(j, j)));
  panel.rootJoint = roots.includes(panel.rootJoint) ? panel.rootJoint : roots[0] ?? null;
  $("root-joint").value = panel.rootJoint ?? "";
  $("ik-joint").replaceChildren(...names.map((j) => new Option(j, j)));
  const chains = names.filter((j) => ancestors(j).length >= 2);
  if (chains.length) $("ik-joint").value = chains[chains.length - 1];
  const kept = (panel.ik?.joints ?? [panel.ik?.joint]).every((j) => names.includes(j));
  if (!kept) panel.ik = panel.sentIk = null;
  showIk();
}

function clipSelected(clip) {
  panel.layers = [{ clip: clip.id, weight: 1, mask: null }];
  panel.ik = null;
  panel.sentIk = null;
  resetTrail();
  for (const id of ["layer-clip", "fade-clip"]) fillClipSelect($(id));
  fillJointSelects();
  renderLayers();
}

/// Another skeleton plays: its joints in the selects and masks, and the
/// motion shown again (`adopted`: a watched broadcast plays it already).
function characterChanged(_, adopted) {
  resetTrail();
  fillJointSelects();
  if (adopted) renderLayers();
  else recompose();
}

/// Layers, masks, root motion and character as a broadcast plays them (a
/// graph's layer is the graph panel's: graph.js).
export function adopt(doc) {
  if ((doc.character ?? null) !== (state.character?.id ?? null)) choose(doc.character ?? "", true).catch(report);
  const clips = doc.layers.filter((l) => l.clip);
  if (clips.length) panel.layers = clips.map((l) => ({ clip: l.clip, weight: l.weight ?? 1, mask: Object.keys(l.mask?.joints || {})[0] ?? null }));
  panel.rootMode = doc.root_motion?.mode ?? "";
  panel.rootJoint = doc.root_motion?.joint ?? panel.rootJoint;
  $("root-mode").value = panel.rootMode;
  const ik = doc.ik?.[0];
  panel.ik = ik && (ik.kind === "aim" || ik.kind === "two_bone") ? { ...ik, joint: ik.joint ?? ik.joints[2] } : null;
  showIk();
  renderLayers();
}

// ---- crossfade ----

function crossfade() {
  const to = $("fade-clip").value;
  if (!to || !state.clip) return;
  if (!state.ws) return selectClip(to).catch(report); // nothing plays: nothing to fade from
  const playback = options().playback;
  panel.fading = panel.layers; // put back if the server refuses the fade
  panel.layers = [{ clip: to, weight: 1, mask: null }];
  const target = { layers: [layerDoc(panel.layers[0], playback)] };
  if (panel.rootMode) target.root_motion = motion().root_motion;
  if (state.character) target.character = state.character.id;
  crossfadeTo(target, fadeSeconds());
  renderLayers();
}

/// A refused crossfade (another skeleton, a clip gone) leaves the layers playing.
function refused() {
  if (!panel.fading) return;
  panel.layers = panel.fading;
  panel.fading = null;
  renderLayers();
}

// ---- root motion: the trail, and the character moved along it under `extract` ----

/// `frame` (the parent's model transform) applied to a point of its space, and back.
const toModel = applyTransform;
const fromModel = unapplyTransform;

/// Joint `i`'s parent's model transform and its own local one, from a
/// pose in either space (docs/clip-format.md §2.8; scales taken per axis, unsheared).
function rootFrames(pose, i) {
  const joints = pose.joints, parents = state.parents;
  const trs = (j) => ({ t: j.translation, q: j.rotation, s: j.scale });
  let parent = IDENTITY;
  if (parents[i] >= 0 && pose.space === "model") parent = trs(joints[parents[i]]);
  else if (parents[i] >= 0) {
    const chain = [];
    for (let p = parents[i]; p >= 0; p = parents[p]) chain.unshift(trs(joints[p]));
    parent = chain.reduce(composeTransforms, IDENTITY);
  }
  const own = trs(joints[i]);
  const local = pose.space === "model" ? { t: fromModel(parent, own.t), q: qmul(conj(parent.q), own.q) } : own;
  return { parent, local };
}

/// Root motion lives in the root joint's parent's space, up its y axis
/// (docs/motion.md): each frame's total `A` placed at the first frame's motion
/// transform `M0` (the root's ground position and heading there) is a
/// trail point `M0·A·0`; under `extract` (the pose kept in place) the
/// skeleton is drawn moved by `M0·A·M0⁻¹`, walking along the trail. Both
/// are mapped to model space by the parent's first-frame transform.
function onFrame(frame) {
  panel.lastFrame = frame;
  if (panel.fading && frame.pose.clip === panel.layers[0]?.clip) panel.fading = null;
  if (frame.pose.clip !== panel.playingClip) {
    panel.playingClip = frame.pose.clip;
    $("playing").textContent = `playing: ${clipName(frame.pose.clip)}`;
    // A crossfade's clip becomes the page's: its range (a `once` end), list entry and curves.
    if (frame.pose.clip !== state.clip?.id && frame.pose.clip !== state.graph?.id) adoptClip(frame.pose.clip).catch(report);
  }
  const total = frame.pose.root_motion?.total;
  if (!total || !panel.rootMode) return;
  if (!panel.anchor) {
    const i = state.names.indexOf(panel.rootJoint);
    if (!frame.pose.joints[i]) return;
    const { parent, local } = rootFrames(frame.pose, i);
    // The first frame shown need not be the stream's first (a starved page
    // shows only the newest): under `report` its root has already moved by
    // `total`, which is taken back to find where the stream started.
    const moved = panel.rootMode !== "extract";
    const yaw = yawOf(local.q) - (moved ? total.yaw : 0);
    const back = moved ? turn(yaw, total.translation) : [0, 0, 0];
    panel.anchor = { parent, ground: [local.t[0] - back[0], 0, local.t[2] - back[2]], yaw };
  }
  const { parent, ground, yaw } = panel.anchor;
  const step = turn(yaw, total.translation);
  const at = [ground[0] + step[0], 0, ground[2] + step[2]];
  panel.trail.push(toModel(parent, at));
  if (panel.trail.length > TRAIL_POINTS) panel.trail.shift();
  if (panel.rootMode === "extract") {
    state.positions = panel.model.map((p) => {
      const x = fromModel(parent, p);
      const r = turn(total.yaw, [x[0] - ground[0], x[1], x[2] - ground[2]]);
      return toModel(parent, [at[0] + r[0], r[1], at[2] + r[2]]);
    });
  }
}

// ---- IK handles ----

function ancestors(name) {
  const parent = new Map(skeletonJoints().map((j) => [j.name, j.parent]));
  const out = [];
  for (let p = parent.get(name); p != null && out.length < 64; p = parent.get(p)) out.push(p);
  return out;
}

/// A handle on the chosen joint: two-bone moves it with its parent and
/// grandparent, aim turns it; the target starts where the joint is (aim:
/// a little in front of it, along +z).
function addHandle() {
  const joint = $("ik-joint").value, kind = $("ik-kind").value;
  const i = state.names.indexOf(joint);
  const at = panel.model[i];
  if (!at) return setStatus(`no pose of ${joint} to start the handle from`, true);
  let joints;
  if (kind === "two_bone") {
    const up = ancestors(joint);
    if (up.length < 2) return setStatus(`two-bone IK needs a joint with a parent and a grandparent; ${joint} has ${up.length ? "only a parent" : "none"}`, true);
    joints = [up[1], up[0], joint];
  }
  const reach = kind === "aim" ? 0.5 * state.camera.radius : 0;
  panel.ik = { kind, joint, joints, target: [at[0], at[1], at[2] + reach] };
  showIk();
  sendIk();
}

function removeHandle() {
  panel.ik = null;
  showIk();
  sendIk();
}

function showIk() {
  $("ik-remove").disabled = !panel.ik;
  $("ik-info").textContent = panel.ik
    ? `${panel.ik.kind === "aim" ? "aim" : "two-bone"} on ${panel.ik.joint}: drag the handle`
    : "pick a joint, then add a handle";
  requestDraw();
}

/// The handle's constraint as a live `ik` control (or the paused view's pose).
const sendIkNow = () => {
  panel.sentIk = panel.ik ? [...panel.ik.target] : null;
  send({ op: "ik", constraints: panel.ik ? [constraint()] : [] });
};
const sendIkThrottled = throttled(sendIkNow);
/// A graph stream's IK is fixed when it opens (docs/graphs.md): the stream
/// opens again with the handle, once a drag ends (`dragging`: not yet).
function sendIk({ dragging = false } = {}) {
  if (state.ws && state.graph) return dragging || reopenGraph();
  if (state.ws) sendIkThrottled();
  else if (state.clip) refreshThrottled();
}
/// The handle's final place, whatever the throttle held back.
const sendIkFinal = () => (state.graph ? reopenGraph() : sendIkNow());
/// The graph's stream opens again (a watched broadcast's motion is its own).
const reopenGraph = () => state.watching || reopen();

function handleOnScreen(cam) {
  const v = toCamera(cam, panel.ik.target);
  if (v[2] <= cam.near) return null;
  return { depth: v[2], at: toScreen(cam, v) };
}

/// The pointer in the scene canvas's pixels.
function pointer(e, cam) {
  const r = $("scene").getBoundingClientRect();
  return [(e.clientX - r.left) * cam.dpr, (e.clientY - r.top) * cam.dpr];
}

// ---- the translate gizmo: three arrows along the world axes from the handle ----

/// The gizmo's arrows on screen: per axis its base and tip (pixels); each
/// as long in the world as GIZMO_PX on screen at the handle's depth.
function gizmoArrows(cam) {
  const base = toCamera(cam, panel.ik.target);
  if (base[2] <= cam.near) return [];
  const length = (GIZMO_PX * cam.dpr * base[2]) / cam.focal;
  return AXES.map((a, axis) => {
    const tip = toCamera(cam, panel.ik.target.map((c, k) => c + a[k] * length));
    return tip[2] <= cam.near ? null : { axis, from: toScreen(cam, base), to: toScreen(cam, tip) };
  }).filter(Boolean);
}

/// Distance from point `p` to segment `a`–`b` (pixels).
function segmentDistance(p, a, b) {
  const d = [b[0] - a[0], b[1] - a[1]];
  const len2 = d[0] * d[0] + d[1] * d[1] || 1;
  const t = Math.max(0, Math.min(1, ((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2));
  return Math.hypot(p[0] - a[0] - t * d[0], p[1] - a[1] - t * d[1]);
}

/// Where along the axis line `origin + t·axis` the pointer's ray passes nearest: `t`.
export function alongAxis(cam, [sx, sy], origin, axis) {
  const x = (sx - cam.cx) / cam.focal, y = -(sy - cam.cy) / cam.focal;
  const ray = [0, 1, 2].map((k) => cam.f[k] + x * cam.r[k] + y * cam.u[k]);
  const n = Math.hypot(...ray);
  const dir = ray.map((c) => c / n);
  const w0 = [0, 1, 2].map((k) => origin[k] - cam.eye[k]);
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const b = dot(axis, dir), d = dot(axis, w0), e = dot(dir, w0);
  const denom = 1 - b * b;
  return denom < 1e-9 ? 0 : (b * e - d) / denom;
}

/// Dragging a handle moves its target in the camera's view plane through
/// it; dragging one of the gizmo's arrows moves it along that world axis;
/// a press elsewhere orbits as before (scene.js never sees this one).
function setupDrag() {
  const view = $("scene-view");
  let drag = null;
  view.addEventListener(
    "pointerdown",
    (e) => {
      if (!panel.ik) return;
      const cam = sceneCamera();
      const handle = handleOnScreen(cam);
      if (!handle) return;
      const [x, y] = pointer(e, cam);
      const onHandle = Math.hypot(x - handle.at[0], y - handle.at[1]) <= GRAB_PX * cam.dpr;
      const arrow = onHandle ? null : gizmoArrows(cam).find((g) => segmentDistance([x, y], g.from, g.to) <= AXIS_GRAB_PX * cam.dpr);
      if (!onHandle && !arrow) return;
      e.stopPropagation();
      e.preventDefault();
      if (arrow) {
        const start = [...panel.ik.target];
        drag = { axis: AXES[arrow.axis], start, t0: alongAxis(cam, [x, y], start, AXES[arrow.axis]) };
      } else drag = { depth: handle.depth, grab: [handle.at[0] - x, handle.at[1] - y] };
      view.setPointerCapture(e.pointerId);
    },
    { capture: true },
  );
  view.addEventListener("pointermove", (e) => {
    if (!drag || !panel.ik) return;
    const cam = sceneCamera();
    const [x, y] = pointer(e, cam);
    if (drag.axis) {
      const t = alongAxis(cam, [x, y], drag.start, drag.axis) - drag.t0;
      panel.ik.target = drag.start.map((c, k) => c + drag.axis[k] * t);
      requestDraw();
      return sendIk({ dragging: true });
    }
    const sx = x + drag.grab[0], sy = y + drag.grab[1];
    const right = ((sx - cam.cx) / cam.focal) * drag.depth, up = (-(sy - cam.cy) / cam.focal) * drag.depth;
    panel.ik.target = [0, 1, 2].map((k) => cam.eye[k] + cam.f[k] * drag.depth + cam.r[k] * right + cam.u[k] * up);
    requestDraw();
    sendIk({ dragging: true });
  });
  const end = () => {
    if (!drag) return;
    drag = null;
    if (state.ws) setTimeout(sendIkFinal, 0);
  };
  view.addEventListener("pointerup", end);
  view.addEventListener("pointercancel", end);
}

/// The trail and the handle, over the scene.
function overlay(ctx, cam, dpr) {
  if (panel.trail.length > 1) {
    ctx.beginPath();
    let open = false;
    for (const p of panel.trail) {
      const v = toCamera(cam, p);
      if (v[2] <= cam.near) {
        open = false;
        continue;
      }
      const [x, y] = toScreen(cam, v);
      open ? ctx.lineTo(x, y) : ctx.moveTo(x, y);
      open = true;
    }
    ctx.strokeStyle = TRAIL_COLOR;
    ctx.lineWidth = 2 * dpr;
    ctx.setLineDash([6 * dpr, 4 * dpr]);
    ctx.stroke();
    ctx.setLineDash([]);
  }
  if (!panel.ik) return;
  const handle = handleOnScreen(cam);
  if (!handle) return;
  const [x, y] = handle.at;
  const effector = state.positions[state.names.indexOf(panel.ik.joint)];
  if (effector) {
    const v = toCamera(cam, effector);
    if (v[2] > cam.near) {
      const [ex, ey] = toScreen(cam, v);
      ctx.beginPath();
      ctx.moveTo(ex, ey);
      ctx.lineTo(x, y);
      ctx.strokeStyle = HANDLE_COLOR;
      ctx.lineWidth = dpr;
      ctx.stroke();
    }
  }
  for (const { axis, from, to } of gizmoArrows(cam)) {
    ctx.beginPath();
    ctx.moveTo(...from);
    ctx.lineTo(...to);
    ctx.strokeStyle = COLORS[axis];
    ctx.lineWidth = 2.5 * dpr;
    ctx.stroke();
    ctx.beginPath();
    ctx.arc(to[0], to[1], 3.5 * dpr, 0, 2 * Math.PI);
    ctx.fillStyle = COLORS[axis];
    ctx.fill();
  }
  const r = HANDLE_PX * dpr;
  ctx.beginPath();
  ctx.arc(x, y, r, 0, 2 * Math.PI);
  ctx.fillStyle = "rgba(58, 209, 230, 0.35)";
  ctx.fill();
  ctx.strokeStyle = HANDLE_COLOR;
  ctx.lineWidth = 2 * dpr;
  ctx.stroke();
  ctx.beginPath();
  ctx.moveTo(x - 1.6 * r, y);
  ctx.lineTo(x + 1.6 * r, y);
  ctx.moveTo(x, y - 1.6 * r);
  ctx.lineTo(x, y + 1.6 * r);
  ctx.lineWidth = dpr;
  ctx.stroke();
}

// ---- wiring ----

export function setup() {
  build();
  on("clipSelected", clipSelected);
  on("characterChanged", characterChanged);
  // A joint picked in the view is the IK joint a new handle goes on.
  on("jointSelected", (name) => name && [...$("ik-joint").options].some((o) => o.value === name) && ($("ik-joint").value = name));
  on("refused", refused);
  on("pose", () => (panel.model = state.positions));
  on("frame", onFrame);
  on("overlay", overlay);
  for (const id of ["layer-clip", "fade-clip"]) $(id).addEventListener("focus", () => fillClipSelect($(id)));
  $("layer-add").addEventListener("click", () => {
    const clip = $("layer-clip").value;
    if (!clip || !state.clip) return;
    panel.layers.push({ clip, weight: 1, mask: null });
    recompose();
  });
  $("fade").addEventListener("click", crossfade);
  $("root-mode").addEventListener("change", () => {
    panel.rootMode = $("root-mode").value;
    resetTrail();
    recompose();
  });
  $("root-joint").addEventListener("change", () => {
    panel.rootJoint = $("root-joint").value || null;
    resetTrail();
    if (panel.rootMode) recompose();
  });
  $("ik-add").addEventListener("click", addHandle);
  $("ik-remove").addEventListener("click", removeHandle);
  setupDrag();
  renderLayers();
  showIk();
}
