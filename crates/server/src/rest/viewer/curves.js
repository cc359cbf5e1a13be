// The curve plot: a joint's channel or a parameter (docs/clip-format.md §3), sampled by
// the server; a rotation as Euler angles in a chosen order or as quaternion
// components; keys marked, and the tangents of cubic Hermite keys drawn as
// handles.

import { postJson } from "./api.js";
import { $, COLORS, setStatus, sizeCanvas, stroke } from "./dom.js";
import { on } from "./events.js";
import { eulerDegrees, nearestBranch, nearestIndex, unwrapSeries } from "./math.js";
import { draw } from "./render.js";
import { requestTimeOf } from "./settings.js";
import { state } from "./state.js";

const CURVE_POINTS = 400; // samples per plotted curve, at most

const PARAM = "param:"; // the curve selector's prefix for parameters

export function setupCurveSelectors() {
  const joints = [];
  for (const t of state.doc.tracks) if (!joints.includes(t.joint)) joints.push(t.joint);
  const select = $("curve-joint");
  select.replaceChildren(...joints.map((j) => new Option(j, j)));
  const params = state.doc.parameters || [];
  if (params.length) {
    const group = document.createElement("optgroup");
    group.label = "parameters";
    group.append(...params.map((p) => new Option(p.name, PARAM + p.name)));
    select.append(group);
  }
  setupChannels();
}

function setupChannels() {
  const joint = $("curve-joint").value;
  const channels = joint.startsWith(PARAM)
    ? ["value"]
    : state.doc.tracks.filter((t) => t.joint === joint).map((t) => t.channel);
  $("curve-channel").replaceChildren(...channels.map((c) => new Option(c, c)));
  showRotationChoice();
}

function showRotationChoice() {
  $("rotation-as").hidden = $("curve-channel").value !== "rotation";
}

/// The track (or parameter) plotted, and how its values come out of a pose.
function curveSource(joint, channel) {
  if (joint.startsWith(PARAM)) {
    const name = joint.slice(PARAM.length);
    const track = (state.doc.parameters || []).find((p) => p.name === name);
    return { track, read: (pose) => pose.parameters[name] };
  }
  const track = state.doc.tracks.find((t) => t.joint === joint && t.channel === channel);
  return { track, read: (pose) => pose.joints.find((j) => j.name === joint)[channel] };
}

/// Curves asked for: answers can come out of order (a setting changed
/// while another curve was on its way), and only the newest is plotted.
let curvesAsked = 0;

export async function loadCurve() {
  const asked = ++curvesAsked;
  const joint = $("curve-joint").value, channel = $("curve-channel").value;
  if (!state.clip || !joint || !channel) {
    state.curve = null;
    return drawCurves();
  }
  const { id, start, end } = state.clip;
  const { track, read } = curveSource(joint, channel);
  const fps = end > start ? Math.min(240, Math.max(1, CURVE_POINTS / (end - start))) : 1;
  const request = { start, end, fps, space: "local", playback: "once", ease: $("ease").value };
  const { poses } = await postJson(`/v1/clips/${encodeURIComponent(id)}/sample`, request);
  if (asked !== curvesAsked) return;
  const times = poses.map((p) => p.time);
  const raw = poses.map(read);
  const euler = channel === "rotation" && $("curve-rotation").value !== "quaternion" ? $("curve-rotation").value : null;
  const values = euler ? unwrapSeries(raw.map((q) => eulerDegrees(q, euler))) : raw;
  const keys = track.times.map((t, i) => {
    const time = requestTimeOf(t);
    const v = track.values[i];
    return { time, clipTime: t, value: euler ? nearestBranch(eulerDegrees(v, euler), values[nearestIndex(times, time)]) : v };
  });
  const tangents = euler ? [] : hermiteHandles(track);
  state.curve = { clip: id, joint, channel, euler, request, times, values, keys, tangents };
  const ends = track.ends ? `, ends ${track.ends}` : "";
  const unit = euler ? ` · Euler ${euler} (${euler[0]} first), degrees` : "";
  $("curve-info").textContent = `${track.interpolation}${ends} · ${track.times.length} keys · ${request.ease}${unit}`;
  drawCurves();
}

/// A cubic Hermite track's tangents as Bezier handles (units per second
/// times a third of the segment): out of key i at `t_i + h_i/3`, into key
/// i at `t_i - h_{i-1}/3`, as docs/clip-format.md §2.5's segment is that Bezier.
function hermiteHandles(track) {
  if (track.interpolation !== "cubic_hermite") return [];
  const { times, values, in_tangents: a, out_tangents: b } = track;
  const at = (i, sign, h, tangent) => ({
    time: requestTimeOf(times[i] + (sign * h) / 3),
    value: values[i].map((v, c) => v + (sign * h * tangent[c]) / 3),
  });
  return times.map((t, i) => ({
    time: requestTimeOf(t),
    value: values[i],
    in: i > 0 ? at(i, -1, t - times[i - 1], a[i]) : null,
    out: i + 1 < times.length ? at(i, 1, times[i + 1] - t, b[i]) : null,
  }));
}

/// Where the plot's time axis lies on the canvas (for the playhead), as the curve layer last drew it.
let plot = null;
/// What the curve layer shows: redrawn only when the curve or the canvas size changes.
let layerKey = null;
/// How often the playhead layer may be redrawn while playing (ms): about 30 times a second.
const PLAYHEAD_INTERVAL = 30;

/// Redraws the curve layer (keys, handles, the curve) at the next animation frame, if the curve or the view changed.
export function drawCurves() {
  draw("curves", () => {
    const canvas = $("curves");
    const dpr = sizeCanvas(canvas);
    const key = [state.curve, canvas.width, canvas.height];
    if (layerKey && key.every((k, i) => k === layerKey[i])) return;
    layerKey = key;
    state.curveLayerDraws = (state.curveLayerDraws || 0) + 1;
    drawCurveLayer(canvas, dpr);
    drawPlayhead();
  });
}

/// Moves the playhead (its own layer over the curve's), about 30 times a second.
export function drawPlayhead() {
  draw("playhead", drawPlayheadNow, PLAYHEAD_INTERVAL);
}

function drawPlayheadNow() {
  const canvas = $("curves-playhead");
  const dpr = sizeCanvas(canvas);
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!plot || !state.curve) return;
  const { t0, t1, left, right, top, bottom } = plot;
  const t = requestTimeOf(state.clipTime);
  const x = left + (t1 > t0 ? ((t - t0) / (t1 - t0)) * (right - left) : 0);
  stroke(ctx, "#ff8c1a", dpr, () => (ctx.moveTo(x, top), ctx.lineTo(x, bottom)));
}

function drawCurveLayer(canvas, dpr) {
  const ctx = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height;
  ctx.fillStyle = "#101216";
  ctx.fillRect(0, 0, W, H);
  plot = null;
  const curve = state.curve;
  if (!curve || !curve.times.length) return;
  const handles = curve.tangents.flatMap((k) => [k.in, k.out].filter(Boolean));
  let lo = Infinity, hi = -Infinity;
  for (const v of [...curve.values, ...curve.keys.map((k) => k.value), ...handles.map((h) => h.value)])
    for (const c of v) {
      lo = Math.min(lo, c);
      hi = Math.max(hi, c);
    }
  if (hi - lo < 1e-6) {
    lo -= 0.5;
    hi += 0.5;
  }
  const pad = 0.08 * (hi - lo);
  lo -= pad;
  hi += pad;
  const t0 = curve.times[0], t1 = curve.times[curve.times.length - 1];
  const left = 48 * dpr, right = W - 12 * dpr, top = 10 * dpr, bottom = H - 20 * dpr;
  plot = { t0, t1, left, right, top, bottom };
  const X = (t) => left + (t1 > t0 ? ((t - t0) / (t1 - t0)) * (right - left) : 0);
  const Y = (v) => bottom - ((v - lo) / (hi - lo)) * (bottom - top);
  ctx.font = `${11 * dpr}px system-ui, sans-serif`;
  ctx.fillStyle = "#8a93a3";
  const unit = curve.euler ? "°" : "";
  ctx.fillText(hi.toPrecision(4) + unit, 4 * dpr, top + 8 * dpr);
  ctx.fillText(lo.toPrecision(4) + unit, 4 * dpr, bottom);
  ctx.fillText(`${t0.toFixed(2)} s`, left, H - 5 * dpr);
  ctx.fillText(`${t1.toFixed(2)} s`, right - 40 * dpr, H - 5 * dpr);
  if (lo < 0 && hi > 0) stroke(ctx, "#353a45", dpr, () => (ctx.moveTo(left, Y(0)), ctx.lineTo(right, Y(0))));
  const components = curve.values[0].length;
  for (let c = 0; c < components; c++) {
    const color = COLORS[c % COLORS.length];
    stroke(ctx, color, 1.5 * dpr, () =>
      curve.times.forEach((t, i) => (i ? ctx.lineTo(X(t), Y(curve.values[i][c])) : ctx.moveTo(X(t), Y(curve.values[i][c])))),
    );
    for (const k of curve.tangents)
      for (const h of [k.in, k.out].filter(Boolean)) {
        stroke(ctx, color, dpr, () => (ctx.moveTo(X(k.time), Y(k.value[c])), ctx.lineTo(X(h.time), Y(h.value[c]))));
        ctx.beginPath();
        ctx.arc(X(h.time), Y(h.value[c]), 3 * dpr, 0, 2 * Math.PI);
        ctx.strokeStyle = color;
        ctx.stroke();
      }
    ctx.fillStyle = color;
    for (const k of curve.keys) ctx.fillRect(X(k.time) - 3 * dpr, Y(k.value[c]) - 3 * dpr, 6 * dpr, 6 * dpr);
  }
}

/// A joint picked in the view plots its first channel, if it has tracks.
function showJoint(name) {
  const select = $("curve-joint");
  if (!name || select.value === name || ![...select.options].some((o) => o.value === name)) return;
  select.value = name;
  setupChannels();
  loadCurve().catch((e) => setStatus(e.message, true));
}

/// The selectors: another curve is plotted as soon as it is chosen.
export function setup() {
  const report = (e) => setStatus(e.message, true);
  on("jointSelected", showJoint);
  $("curve-joint").addEventListener("change", () => {
    setupChannels();
    loadCurve().catch(report);
  });
  $("curve-channel").addEventListener("change", () => {
    showRotationChoice();
    loadCurve().catch(report);
  });
  $("curve-rotation").addEventListener("change", () => loadCurve().catch(report));
}
