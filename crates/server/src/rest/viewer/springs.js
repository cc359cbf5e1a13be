// Springs on the page's motion (docs/springs.md): the clip's own chains are
// listed and drawn; a chain can be added from a joint down its first
// descendants (a tail, an ear, a ponytail), with one stiffness, drag and
// gravity for the page's chains; **on** sends them in the motion's
// `springs` (which replace the clip's), **Reset** sends `reset_springs`.
// The chains are drawn over the view, and their colliders as circles.

import { panel } from "./composition.js";
import { send } from "./controls.js";
import { $, el, row } from "./dom.js";
import { on } from "./events.js";
import { applyTransform, modelTransforms, toCamera, toScreen } from "./math.js";
import { reopen } from "./player.js";
import { requestDraw } from "./scene.js";
import { shownSkeleton, state } from "./state.js";

const CHAIN_COLOR = "#ff8c1a";
const COLLIDER_COLOR = "rgba(255, 140, 26, 0.6)";
/// Words of joint names that usually start a chain, for the picker's first choice.
const SWINGY = new Set(["tail", "hair", "ponytail", "pony", "ear", "ears", "cape", "skirt", "braid"]);

/// Whether a joint's name has a swingy word (`b_Tail01`, `LeftEar`; not `ForeArm`).
const swingy = (name) => name.replace(/([a-z])([A-Z])/g, "$1 $2").toLowerCase().split(/[^a-z]+/).some((w) => SWINGY.has(w));

const springs = panel.springs;
let model = []; // the pose shown's model transforms, when there are colliders to place

// ---- the pure parts (unit-tested: tests/springs.test.js) ----

/// The chain from `root` down its first child at each step to a leaf, as
/// joint names, given each joint's `{name, parent}` in skeleton order.
export function chainFrom(joints, root) {
  const chain = [root];
  for (;;) {
    const child = joints.find((j) => j.parent === chain.at(-1));
    if (!child) return chain;
    chain.push(child.name);
  }
}

/// The joints a chain can start at (at least one descendant, in no chain
/// yet), the likeliest (by name) first.
export function chainRoots(joints, taken = new Set()) {
  const free = joints.filter((j) => !taken.has(j.name) && joints.some((c) => c.parent === j.name));
  return [...free.filter((j) => swingy(j.name)), ...free.filter((j) => !swingy(j.name))].map((j) => j.name);
}

// ---- the panel ----

const joints = () => shownSkeleton()?.joints ?? [];
const ownChains = () => (state.character || state.graph ? [] : (state.doc?.springs ?? []));
const taken = () => new Set(springs.chains.flatMap((c) => c.joints.slice(0, -1)));

function renderChains() {
  const own = ownChains();
  $("springs-own").textContent = own.length
    ? `the clip's own: ${own.map((c) => c.name).join(", ")}${springs.on && springs.chains.length ? " (replaced by the page's)" : ""}`
    : "";
  const items = springs.chains.map((chain, i) => {
    const remove = el("button", { type: "button", textContent: "×", title: "Remove this chain" });
    remove.addEventListener("click", () => {
      springs.chains.splice(i, 1);
      changed();
    });
    return el("li", {}, row(el("span", { className: "name", textContent: `${chain.name}: ${chain.joints.length} joints` }), remove));
  });
  $("springs-chains").replaceChildren(...items);
  $("spring-root").replaceChildren(...chainRoots(joints(), taken()).map((j) => new Option(j, j)));
}

/// The motion changed: the stream (or the paused pose) follows.
function changed() {
  renderChains();
  requestDraw();
  if (!state.watching) reopen();
}

function addChain() {
  const root = $("spring-root").value;
  if (!root) return;
  const chain = chainFrom(joints(), root);
  springs.chains.push({ name: root, joints: chain });
  changed();
}

function slider(id, label, min, max, step, key) {
  const input = el("input", { id, type: "range", min: String(min), max: String(max), step: String(step), value: String(springs[key]), ariaLabel: label });
  const shown = el("span", { className: "weight", textContent: springs[key].toFixed(2) });
  input.addEventListener("input", () => (shown.textContent = Number(input.value).toFixed(2)));
  input.addEventListener("change", () => {
    springs[key] = Number(input.value);
    if (springs.chains.length) changed();
  });
  return row(el("span", { className: "name", textContent: label }), input, shown);
}

// ---- drawing ----

/// `p` on the screen, and a world `radius` there in pixels; null behind the camera.
function project(cam, p, radius = 0) {
  const v = toCamera(cam, p);
  if (v[2] <= 1e-6) return null;
  return [...toScreen(cam, v), (radius * cam.focal) / v[2]];
}

function overlay(ctx, cam, dpr) {
  const index = new Map(state.names.map((n, i) => [n, i]));
  const chains = springs.on && springs.chains.length ? springs.chains : ownChains();
  const point = (name) => state.positions[index.get(name)];
  ctx.lineCap = "round";
  for (const chain of chains) {
    const points = chain.joints.map(point).filter(Boolean).map((p) => project(cam, p)).filter(Boolean);
    ctx.beginPath();
    points.forEach(([x, y], k) => (k ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.strokeStyle = CHAIN_COLOR;
    ctx.lineWidth = 3 * dpr;
    ctx.stroke();
    for (const collider of chain.colliders ?? []) drawCollider(ctx, cam, dpr, collider, index);
  }
}

/// A sphere as a circle at its centre; a capsule as its two end circles and the line between.
function drawCollider(ctx, cam, dpr, collider, index) {
  const frame = model[index.get(collider.joint)];
  if (!frame) return;
  const shape = collider.sphere ?? collider.capsule;
  const ends = [shape.offset, ...(collider.capsule ? [shape.tail] : [])].map((o) => applyTransform(frame, o ?? [0, 0, 0]));
  const circles = ends.map((p) => project(cam, p, shape.radius)).filter(Boolean);
  ctx.beginPath();
  for (const [x, y, r] of circles) {
    ctx.moveTo(x + r, y);
    ctx.arc(x, y, r, 0, 2 * Math.PI);
  }
  if (circles.length === 2) ctx.moveTo(circles[0][0], circles[0][1]), ctx.lineTo(circles[1][0], circles[1][1]);
  ctx.strokeStyle = COLLIDER_COLOR;
  ctx.lineWidth = dpr;
  ctx.stroke();
}

/// The model transforms of a pose, kept only when there are colliders to place.
function keepModel(pose) {
  const colliders = ownChains().some((c) => c.colliders?.length);
  if (!colliders || pose.space === "model") return void (model = []);
  model = modelTransforms(pose.joints.map((j) => ({ t: j.translation, q: j.rotation, s: j.scale })), state.parents);
}

export function setup() {
  const section = el(
    "section",
    { id: "springs-panel" },
    el("h2", { textContent: "Springs" }),
    el("p", { id: "springs-own", className: "info" }),
    el("ul", { id: "springs-chains", className: "info" }),
    row(el("select", { id: "spring-root", ariaLabel: "Joint a chain starts at" }), el("button", { id: "spring-add", type: "button", textContent: "Add chain" })),
    slider("spring-stiffness", "stiffness", 0, 4, 0.05, "stiffness"),
    slider("spring-drag", "drag", 0, 1, 0.01, "drag"),
    slider("spring-gravity", "gravity", 0, 20, 0.1, "gravity"),
    row(
      el("label", {}, el("input", { id: "springs-on", type: "checkbox", checked: true }), " on"),
      el("button", { id: "springs-reset", type: "button", textContent: "Reset", title: "Restart the chains at rest" }),
    ),
  );
  $("ik-panel").after(section);
  $("spring-add").addEventListener("click", addChain);
  $("springs-on").addEventListener("change", () => {
    springs.on = $("springs-on").checked;
    if (springs.chains.length) changed();
  });
  $("springs-reset").addEventListener("click", () => send({ op: "reset_springs" }));
  on("clipSelected", () => ((springs.chains = []), renderChains()));
  on("characterChanged", () => ((springs.chains = []), renderChains()));
  on("pose", keepModel);
  on("overlay", overlay);
  renderChains();
}
