// The motion the page plays (docs/motion.md): the selected clip as the first
// layer, more layers with weights and masks, root motion and an IK handle
// (panel.js edits them). A stream opens `/v1/stream` with this motion, and a
// paused view of a composition asks `POST /v1/poses` for it.

import { postJson } from "./api.js";
import { $ } from "./dom.js";
import { fps, options } from "./settings.js";
import { state } from "./state.js";

export const panel = {
  layers: [], // [{clip, weight, mask: joint name | null}]; the first is the selected clip
  rootMode: "", // "" (off), "report" or "extract"
  rootJoint: null,
  anchor: null, // the root's ground position and heading at the stream's first frame
  trail: [], // root ground positions, world space
  ik: null, // {kind, joint, joints?, target}: the handle
  sentIk: null, // the target last sent
  model: [], // the model-space joint positions of the pose shown, before root motion moves them
  playingClip: null, // the clip the frames say is playing (the first layer's)
  lastFrame: null,
  openPaused: false, // the next stream opens paused (a change made while paused)
  fading: null, // the layers before a crossfade the server has not shown yet
  springs: { chains: [], on: true, stiffness: 1, drag: 0.4, gravity: 9.81 }, // the page's chains ({name, joints}) and their settings (springs.js)
  motion, // the motion doc, as `motion()` below (read by the browser test)
};

/// Whether the page shows more than its clip: another layer, a weight, a
/// mask, root motion, IK or a character (a plain clip keeps the clip routes).
export function composed() {
  const [base, ...rest] = panel.layers;
  if (state.graph) return true;
  const springs = panel.springs.on && panel.springs.chains.length;
  return Boolean(rest.length || (base && (base.weight !== 1 || base.mask)) || panel.rootMode || panel.ik || state.character || springs);
}

export function layerDoc(layer, playback) {
  const doc = { clip: layer.clip };
  if (layer.weight !== 1) doc.weight = layer.weight;
  if (layer.mask) doc.mask = { joints: { [layer.mask]: 1 }, descendants: true };
  if (playback) doc.playback = playback;
  return doc;
}

/// The motion the page plays (docs/motion.md), IK included unless `ik` is
/// false (a crossfade's motion carries none: a stream has one IK list). A
/// graph is its only layer, with the page's root motion, IK, character and
/// springs all the same (docs/graphs.md, “What composes with a graph”).
export function motion({ ik = true } = {}) {
  const doc = { layers: state.graph ? [{ graph: state.graph.id }] : clipLayers() };
  if (panel.rootMode) doc.root_motion = { mode: panel.rootMode, ...(panel.rootJoint ? { joint: panel.rootJoint } : {}) };
  if (ik && panel.ik) doc.ik = [constraint()];
  if (state.character) doc.character = state.character.id;
  return withSprings(doc, panel.springs);
}

/// The page's clip layers, at the playback the page chooses.
function clipLayers() {
  const playback = options().playback;
  return panel.layers.map((l) => layerDoc(l, playback));
}

/// A motion `doc` with the page's chains as its `springs` when they are on:
/// a graph's pose takes them as a clip's does (docs/graphs.md, “What
/// composes with a graph”).
export function withSprings(doc, springs) {
  return springs.on && springs.chains.length ? { ...doc, springs: springsDoc(springs) } : doc;
}

/// A graph's settings that hold (floats and bools; a trigger lasts one tick),
/// from its controls (graph.js).
export const heldSettings = (controls) =>
  Object.fromEntries(controls.filter((c) => c.kind !== "trigger").map((c) => [c.name, c.value]));

/// The page's chains as the motion's `springs` (docs/springs.md, “Fields”):
/// one stiffness, drag and downward gravity for all.
export const springsDoc = (s) =>
  s.chains.map(({ name, joints }) => ({ name, joints, stiffness: s.stiffness, drag: s.drag, gravity: [0, -s.gravity, 0] }));

/// The handle as an IK constraint.
export function constraint() {
  const { kind, joint, joints, target } = panel.ik;
  return kind === "aim" ? { kind, joint, target } : { kind, joints, target };
}

export function resetTrail() {
  panel.anchor = null;
  panel.trail = [];
}

/// The `open` message of a new stream of the motion, with the page's
/// settings (a new stream starts a new root-motion trail).
export function openMessage() {
  const { space, ease } = options();
  const open = {
    op: "open",
    motion: motion(),
    fps: fps(),
    speed: Number($("speed").value) || 1,
    start: state.graph ? 0 : state.requestTime, // a graph plays from its tick 0 (docs/graphs.md)
    space,
    ease,
    paused: panel.openPaused,
    ...(state.graph ? { report: true } : {}),
  };
  panel.openPaused = false;
  resetTrail();
  return open;
}

/// The paused view's pose of a composition at `t` (`POST /v1/poses`; ease
/// is a stream setting), or null for a plain clip. A graph's is played from
/// 0 with the page's settings (docs/graphs.md).
export function composedPoseAt(t) {
  if (!composed()) return null;
  const body = { motion: motion(), time: t, space: options().space };
  if (state.graph) Object.assign(body, { inputs: [{ time: 0, set: heldSettings(state.graph.controls) }], fps: fps(), report: true });
  return postJson("/v1/poses", body);
}
