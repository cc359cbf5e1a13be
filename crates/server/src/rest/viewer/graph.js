// The graph the page plays (docs/graphs.md): picked in the graph panel, it
// is the motion's only layer, with the page's character, root motion, IK
// handle and spring chains (composition.js). Each parameter gets a control — a slider for
// a float, a box for a bool, a button for a trigger — whose changes go to
// the stream (or the watched broadcast) as live `set` controls; each frame's
// report (the state, a transition in progress, the blend weights) is shown.
// Paused, the view asks `POST /v1/poses` for the graph with the settings as
// inputs at time 0.

import { api, listAll } from "./api.js";
import { selectClip } from "./clips.js";
import { heldSettings } from "./composition.js";
import { send } from "./controls.js";
import { $, dispatchStatus, el, row, setStatus } from "./dom.js";
import { on } from "./events.js";
import { reopen, showPoseAt } from "./player.js";
import { fps } from "./settings.js";
import { state } from "./state.js";

// ---- the pure parts (unit-tested: tests/graph.test.js) ----

/// One control per parameter of a graph document, in the document's order:
/// `{name, kind, min, max, value}` (a float's range and default; a bool's
/// default; a trigger has neither).
export function parameterControls(doc) {
  return Object.entries(doc.parameters || {}).map(([name, p]) => {
    if (p.type === "float") {
      const min = p.min ?? 0, max = p.max ?? 1;
      return { name, kind: "float", min, max, value: Math.min(max, Math.max(min, p.default ?? 0)) };
    }
    if (p.type === "bool") return { name, kind: "bool", value: Boolean(p.default) };
    return { name, kind: "trigger" };
  });
}

/// A frame's report as text: the state, and a transition with its α.
export function describeState(report) {
  if (!report) return "";
  const t = report.transition;
  return t ? `${t.from} → ${t.to} (α ${t.alpha.toFixed(2)})` : report.state;
}

/// A blend node's weights as `name weight` pairs, heaviest first, the
/// points named by their clips' names (`names`: clip id → name).
export function describeWeights(doc, node, weights, names = {}) {
  const blend = doc.nodes?.[node]?.blend1d ?? doc.nodes?.[node]?.blend2d;
  const label = (i) => {
    const clip = blend?.points?.[i]?.clip ?? `point ${i}`;
    return names[clip] ?? clip.replace(/^name:/, "");
  };
  return weights
    .map((w, i) => ({ name: label(i), weight: w }))
    .filter((p) => p.weight > 0)
    .sort((a, b) => b.weight - a.weight);
}

/// The clip a graph's poses take their skeleton from (the graph's output
/// skeleton): the initial state's node's first clip, or the output node's,
/// through a blend's first point and a stack's first entry. `null` when the
/// document names none.
export function outputClip(doc) {
  let name = doc.machine ? doc.machine.states?.[doc.machine.initial]?.node : doc.output;
  for (let hops = 0; hops <= Object.keys(doc.nodes || {}).length; hops++) {
    const node = doc.nodes?.[name];
    const first = node?.clip ? node : (node?.blend1d ?? node?.blend2d)?.points?.[0] ?? node?.layers?.[0];
    if (!first) return null;
    if (first.clip) return first.clip;
    name = first.node;
  }
  return null; // a cycle (the server refuses those)
}

/// A clip reference's id: `name:<name>` looked up in `clips`, else the id itself.
export const clipIdOf = (ref, clips) => (ref?.startsWith("name:") ? clips.find((c) => c.name === ref.slice(5))?.id : ref) ?? null;

// ---- the panel ----

const report = (e) => setStatus(e.message, true);

async function loadGraphs() {
  state.graphs = await listAll("/v1/graphs", "graphs");
}

function fill() {
  const select = $("graph");
  const options = state.graphs.map((g) => new Option(g.name, g.id));
  select.replaceChildren(new Option("none: play the layers", ""), ...options);
  select.value = state.graph?.id ?? "";
}

const refresh = (quiet = false) =>
  loadGraphs()
    .then(fill)
    .catch((e) => quiet || setStatus(`listing graphs: ${e.message}`, true));

/// Plays graph `id` (empty: back to the layers). The clip of its output
/// skeleton becomes the page's clip, for the skeleton, joints, mesh and framing.
/// `quiet`: a watched broadcast plays it already (no stream of the page's own).
export async function choose(id, { quiet = false } = {}) {
  const summary = id ? state.graphs.find((g) => g.id === id) ?? (await api(`/v1/graphs/${encodeURIComponent(id)}`)) : null;
  if (!summary) return forget(quiet);
  const doc = await api(`/v1/graphs/${encodeURIComponent(id)}`);
  if (!state.graphs.some((g) => g.id === id)) {
    state.graphs.push({ ...summary, id }); // a watched broadcast's graph, before the list is read
    fill();
  }
  const first = clipIdOf(outputClip(doc), state.clips) ?? summary.clips?.[0];
  choosing = true;
  try {
    if (first && state.clip?.id !== first) await selectClip(first);
  } finally {
    choosing = false;
  }
  state.graph = { id, name: summary.name, doc, controls: parameterControls(doc) };
  dispatchStatus({ type: "graph", name: summary.name });
  renderControls();
  showGraphing();
  if (!quiet) restart();
}

let choosing = false; // selecting the graph's clip (which is not leaving the graph)

/// Back to the layers ("none"); `quiet` when another clip was picked, which shows itself,
/// or a watched broadcast plays its layers.
function forget(quiet = false) {
  if (!state.graph) return;
  state.graph = null;
  dispatchStatus({ type: "graph", name: null });
  renderControls();
  showGraphing();
  if (!quiet) restart();
}

/// A running stream opens again over the new motion (a watched broadcast plays its own).
const restart = () => state.watching || reopen();

function showGraphing() {
  document.body.classList.toggle("graphing", Boolean(state.graph));
  $("graph").value = state.graph?.id ?? "";
  $("graph-state").textContent = state.graph ? "paused: press Play to run the graph" : "";
  $("graph-weights").replaceChildren();
}

/// A setting: to the stream or broadcast when one runs, else a new paused pose.
function set(name, value) {
  if (state.ws || state.watching) return send({ op: "set", parameters: { [name]: value } });
  showPoseAt(state.requestTime).catch(report);
}

function renderControls() {
  const controls = state.graph?.controls ?? [];
  $("graph-parameters").replaceChildren(...controls.map(controlRow));
}

function controlRow(c) {
  if (c.kind === "trigger") {
    const button = el("button", { id: `graph-${c.name}`, type: "button", textContent: c.name });
    button.addEventListener("click", () => set(c.name, true));
    return row(button);
  }
  if (c.kind === "bool") {
    const box = el("input", { id: `graph-${c.name}`, type: "checkbox", checked: c.value, ariaLabel: c.name });
    box.addEventListener("change", () => set(c.name, (c.value = box.checked)));
    return row(el("label", {}, box, ` ${c.name}`));
  }
  const step = (c.max - c.min) / 100;
  const slider = el("input", { id: `graph-${c.name}`, type: "range", min: String(c.min), max: String(c.max), step: String(step), value: String(c.value), ariaLabel: c.name });
  const shown = el("span", { className: "weight", textContent: c.value.toFixed(2) });
  const sendLatest = throttled(() => set(c.name, c.value));
  slider.addEventListener("input", () => {
    c.value = Number(slider.value);
    shown.textContent = c.value.toFixed(2);
    sendLatest();
  });
  return row(el("span", { className: "name", textContent: c.name }), slider, shown);
}

/// `f` at most once per frame of the stream, the last call always made.
function throttled(f) {
  let timer = null;
  return () => {
    if (timer) return;
    timer = setTimeout(() => {
      timer = null;
      f();
    }, 1000 / fps());
  };
}

/// A frame's (or a paused pose's) report, shown.
function showReport(graphReport) {
  if (!state.graph || !graphReport) return;
  $("graph-state").textContent = describeState(graphReport);
  const names = Object.fromEntries(state.clips.map((c) => [c.id, c.name]));
  const rows = Object.entries(graphReport.weights || {}).map(([node, weights]) => {
    const parts = describeWeights(state.graph.doc, node, weights, names).map((p) => `${p.name} ${p.weight.toFixed(2)}`);
    return el("li", { textContent: `${node}: ${parts.join(" · ")}` });
  });
  $("graph-weights").replaceChildren(...rows);
}

export function setup() {
  const section = el(
    "section",
    { id: "graph-panel" },
    el("h2", { textContent: "Graph" }),
    row(el("select", { id: "graph", ariaLabel: "Graph to play" })),
    el("div", { id: "graph-parameters" }),
    el("p", { id: "graph-state", className: "info" }),
    el("ul", { id: "graph-weights", className: "info" }),
  );
  $("composition").after(section);
  const select = $("graph");
  select.addEventListener("focus", () => refresh());
  select.addEventListener("change", () => choose(select.value).catch(report));
  // A stream starts from the graph's defaults: the settings the page holds follow it.
  on("opened", () => state.graph && !state.watching && send({ op: "set", parameters: heldSettings(state.graph.controls) }));
  on("frame", (frame) => showReport(frame.graph));
  on("pose", (pose) => showReport(pose.graph));
  on("clipSelected", () => choosing || forget(true));
  fill();
  return refresh(true);
}
