// The player: the stream (a WebSocket of frames), play, pause, seek,
// speed and the keys, a `once` stream's end, the paused view's pose, and the
// readout (seq, clip time, dropped ticks, latency, frames).

import { api, describeProblem, socketUrl, streamProtocols } from "./api.js";
import { CompactDecoder } from "./compact.js";
import { composed, composedPoseAt, openMessage, panel } from "./composition.js";
import { refusedControl, send } from "./controls.js";
import { drawPlayhead, loadCurve } from "./curves.js";
import { $, dispatchStatus, setStatus } from "./dom.js";
import { emit } from "./events.js";
import { applyPose } from "./pose.js";
import { update } from "./render.js";
import { fps, options, playbackMode, requestTimeOf } from "./settings.js";
import { state } from "./state.js";
import { formatBytes, formatMs } from "./status.js";

let seeking = false; // the seek bar is held: the readout leaves it alone

/// Shows the pose at `t`. Answers can arrive out of order (the browser
/// spreads requests over connections), so only the newest request's answer
/// is shown, and none once a stream has opened since.
export async function showPoseAt(t) {
  const asked = ++state.poseAsked;
  const q = new URLSearchParams({ t: String(t), ...options() });
  const composed = composedPoseAt(t);
  const pose = await (composed || api(`/v1/clips/${encodeURIComponent(state.clip.id)}/pose?${q}`));
  if (asked !== state.poseAsked) return;
  applyPose(pose);
  updateReadout();
}

/// The page's motion changed: a running stream opens again with it, from the
/// time shown and playing or paused as it was; a paused view asks for its pose.
export function reopen() {
  if (state.ws) {
    const playing = state.playing;
    panel.openPaused = !playing;
    stopStream();
    if (openStream()) setPlaying(playing);
    return;
  }
  if (state.clip) showPoseAt(state.requestTime).catch((e) => setStatus(e.message, true));
}

/// Whether the stream asks for compact frames (docs/compact-frames.md): when
/// chosen, for a plain clip or a graph (in local space; a graph's report
/// comes in each frame's graph report section).
const compactFrames = () => $("encoding").value === "compact" && (!composed() || Boolean(state.graph)) && !state.watching;

/// What a new stream connects to: the watched broadcast's stream, else
/// `/v1/stream` opened with the page's motion (docs/motion.md).
function streamTarget() {
  if (state.watching) return { url: socketUrl(`/v1/broadcasts/${encodeURIComponent(state.watching)}/stream`) };
  const open = openMessage();
  if (compactFrames()) Object.assign(open, { encoding: "compact", space: "local" });
  return { url: socketUrl("/v1/stream"), open };
}

/// A compact frame as the page's JSON frame: its header, events, local pose,
/// root motion and graph report.
function fromCompact(decoder, data) {
  const f = decoder.decode(new Uint8Array(data));
  const part = (a, n, i) => Array.from(a.subarray(n * i, n * i + n));
  const joints = decoder.names.map((name, i) => ({
    name,
    translation: part(f.translations, 3, i),
    rotation: part(f.rotations, 4, i),
    scale: part(f.scales, 3, i),
  }));
  const pose = { space: "local", time: f.clipTime, clip_time: f.clipTime, joints };
  const planar = ([x, y, z, yaw]) => ({ translation: [x, y, z], yaw });
  if (f.rootMotion) pose.root_motion = { delta: planar(f.rootMotion.delta), total: planar(f.rootMotion.total) };
  const events = f.events.map(({ time, name }) => ({ time, name }));
  const frame = { seq: f.seq, dropped: f.dropped, clip_time: f.clipTime, sent_at_unix_nanos: Number(f.sentAtUnixNanos), events, pose };
  if (f.graph) frame.graph = f.graph;
  return frame;
}

/// The bytes a stream received over the last second.
function byteRate() {
  const window = []; // [ms, bytes]
  return (bytes) => {
    const now = performance.now();
    window.push([now, bytes]);
    while (window[0][0] < now - 1000) window.shift();
    return window.reduce((sum, [, b]) => sum + b, 0);
  };
}

/// What the page can check itself before opening a stream (the server
/// refuses a bad handshake with a body the WebSocket API cannot read).
function streamSettingsProblem() {
  const rate = Number($("fps").value), speed = Number($("speed").value);
  if (!(Number.isInteger(rate) && rate >= 1 && rate <= 240)) return `fps must be a whole number from 1 to 240, not "${$("fps").value}"`;
  if (!(Number.isFinite(speed) && Math.abs(speed) <= 1000)) return `speed must be a number within ±1000, not "${$("speed").value}"`;
  return null;
}

/// Why a stream closed before its first frame: the handshake was refused,
/// and the clip's own route says why (a token, a deleted clip), else the
/// stream caps.
async function explainRefusedStream(e) {
  try {
    await api(`/v1/clips/${encodeURIComponent(state.clip.id)}`);
    setStatus(`the server refused the stream (${e.code}${e.reason ? `: ${e.reason}` : ""})`, true);
  } catch (err) {
    setStatus(`stream refused: ${err.message}`, true);
  }
}

export function openStream() {
  const settings = streamSettingsProblem();
  if (settings) {
    setStatus(settings, true);
    return false;
  }
  const target = streamTarget();
  const ws = new WebSocket(target.url, streamProtocols());
  state.poseAsked += 1; // a paused pose still on its way is older than the stream
  if (target.open) ws.onopen = () => ws.send(JSON.stringify(target.open));
  state.ws = ws;
  state.speed = Number($("speed").value) || 1;
  setEnded(false);
  // The readout counts this stream's ticks: each frame's `dropped` is the
  // ticks skipped since the previous frame, so the total is their sum. The
  // counts go into the state with the frame they came with, when it is shown.
  Object.assign(state, { frames: 0, seq: null, dropped: 0 });
  const tally = { frames: 0, dropped: 0 };
  const rate = byteRate();
  let decoder = null; // the compact layout's, from `opened`
  ws.binaryType = "arraybuffer";
  ws.onmessage = (message) => {
    const text = typeof message.data === "string";
    state.bytesPerSecond = rate(text ? message.data.length : message.data.byteLength);
    if (!text && !decoder) return;
    const frame = text ? JSON.parse(message.data) : fromCompact(decoder, message.data);
    if (frame.opened) {
      state.compactLayout = frame.opened.compact ?? null;
      decoder = state.compactLayout ? new CompactDecoder(state.compactLayout) : null;
      return emit("opened", frame.opened);
    }
    // A new layout mid-stream (a control left the old one): the frames after it decode in it.
    if (frame.layout && decoder) return decoder.relayout(frame.layout);
    if (frame.error && target.open && !tally.frames) return setStatus(`stream refused: ${describeProblem(frame.error)}`, true);
    if (frame.error) return refusedControl(frame.error);
    const nowNanos = (performance.timeOrigin + performance.now()) * 1e6;
    tally.frames += 1;
    tally.dropped += frame.dropped;
    if (tally.frames === 1) state.firstClipTime = frame.clip_time;
    if (frame.events?.length) setStatus(`event: ${frame.events.map((e) => e.name).join(", ")}`);
    emit("received", frame);
    // Shown at the next animation frame: only the newest of the frames that came meanwhile.
    const counts = { frames: tally.frames, dropped: tally.dropped, seq: frame.seq, latencyMs: (nowNanos - frame.sent_at_unix_nanos) / 1e6 };
    state.pendingFrame = { frame, counts };
    update("frame", showPendingFrame);
  };
  ws.onclose = (e) => {
    if (state.ws !== ws) return;
    state.ws = null;
    setPlaying(false);
    if (!tally.frames && e.code === 1006) explainRefusedStream(e);
    else if (e.code !== 1000 && e.code !== 1005) setStatus(`stream closed (${e.code}) ${e.reason}`, true);
  };
  return true;
}

/// Shows the newest frame received (render.js calls it once per animation
/// frame at most): its pose, the page's listeners, the readout, and how
/// late it is shown.
function showPendingFrame() {
  if (!state.pendingFrame) return;
  const { frame, counts } = state.pendingFrame;
  state.pendingFrame = null;
  Object.assign(state, counts);
  applyPose(frame.pose);
  emit("frame", frame);
  state.lateMs = ((performance.timeOrigin + performance.now()) * 1e6 - frame.sent_at_unix_nanos) / 1e6;
  updateReadout();
  if (state.playing && state.ws && reachedEnd(frame.clip_time)) endOnce();
}

/// Whether a `once` stream has reached the end it is heading for (a `once`
/// clip holds its last pose; the stream would go on sending it).
function reachedEnd(clipTime) {
  if (playbackMode() !== "once" || !state.clip || state.watching) return false;
  const { start, end } = state.clip;
  return state.speed >= 0 ? clipTime >= end : clipTime <= start;
}

/// A `once` stream ended: close it and let Play start it over.
function endOnce() {
  stopStream();
  setEnded(true);
  dispatchStatus({ type: "ended", time: state.clipTime });
}

export function setEnded(ended) {
  state.ended = ended;
  if (!ended && state.status.mode === "ended") dispatchStatus({ type: "pause" });
  $("play").classList.toggle("ended", ended);
  $("play").title = ended ? "Ended: play again from the start" : "";
}

export function stopStream() {
  const ws = state.ws;
  state.ws = null;
  state.playing = false;
  state.pendingFrame = null;
  if (ws) {
    if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ op: "stop" }));
    ws.close();
  }
  setPlaying(false);
}

/// Settings a running stream cannot change: start a new one from here.
function restartStream() {
  if (!state.clip) return;
  loadCurve().catch((e) => setStatus(e.message, true));
  if (!state.ws) return showPoseAt(state.requestTime).catch((e) => setStatus(e.message, true));
  const wasPlaying = state.playing;
  stopStream();
  if (!wasPlaying) return showPoseAt(state.requestTime).catch((e) => setStatus(e.message, true));
  if (openStream()) setPlaying(true);
}

export function setPlaying(playing) {
  state.playing = playing;
  $("play").textContent = playing ? "Pause" : "Play";
  if (!state.ended || playing) dispatchStatus({ type: playing ? "play" : "pause" });
}

function togglePlay() {
  if (!state.clip) return;
  if (!state.ws) {
    // After a `once` end (or from its very end) play starts over.
    const speed = Number($("speed").value) || 1;
    if (state.ended || (playbackMode() === "once" && atEnd(speed))) {
      state.requestTime = speed >= 0 ? state.clip.start : state.clip.end;
    }
    if (openStream()) setPlaying(true);
  } else {
    send({ op: state.playing ? "pause" : "play" });
    setPlaying(!state.playing);
  }
}

function atEnd(speed) {
  const { start, end } = state.clip;
  return speed >= 0 ? state.clipTime >= end : state.clipTime <= start;
}

/// Moves the playhead to request time `t` (clamped to the clip): a
/// `seek` on a running stream, else a pose fetched for the paused view.
function seekTo(t) {
  if (!state.clip) return;
  const { start, end } = state.clip;
  const time = Math.min(end, Math.max(start, t));
  setEnded(false);
  if (state.ws) send({ op: "seek", time });
  else showPoseAt(time).catch((e) => setStatus(e.message, true));
}

/// Space plays or pauses, arrows step one frame (Shift: one second),
/// Home and End go to the clip's ends. Keys typed into a field are its own.
function onKey(e) {
  const t = e.target;
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  if (t instanceof HTMLElement && t.closest("input, select, textarea")) return;
  // A focused button takes Space itself (it clicks).
  if (e.key === " " && t instanceof HTMLElement && t.closest("button")) return;
  if (!state.clip || $("play").hidden) return; // hidden: a read-only viewer of a broadcast
  const here = Number($("seek").value);
  const step = e.shiftKey ? 1 : 1 / fps();
  const actions = {
    " ": togglePlay,
    ArrowLeft: () => seekTo(here - step),
    ArrowRight: () => seekTo(here + step),
    Home: () => seekTo(state.clip.start),
    End: () => seekTo(state.clip.end),
  };
  const action = actions[e.key];
  if (!action) return;
  e.preventDefault();
  action();
}

export function updateReadout() {
  $("seq").textContent = state.seq ?? "–";
  $("clip-time").textContent = `${state.clipTime.toFixed(3)} s`;
  $("dropped").textContent = state.seq == null ? "–" : state.dropped;
  $("latency").textContent = state.latencyMs == null ? "–" : formatMs(state.latencyMs);
  $("late").textContent = state.lateMs == null ? "–" : formatMs(state.lateMs);
  $("frames").textContent = state.frames;
  $("rate").textContent = state.ws && state.bytesPerSecond != null ? formatBytes(state.bytesPerSecond) : "–";
  if (!seeking) $("seek").value = requestTimeOf(state.clipTime);
  drawPlayhead();
}

/// The play button, the seek bar, the speed box, the keys, and the
/// settings a running stream cannot change.
export function setup() {
  const report = (e) => setStatus(e.message, true);
  $("play").addEventListener("click", togglePlay);
  const seek = $("seek");
  seek.addEventListener("pointerdown", () => (seeking = true));
  seek.addEventListener("change", () => (seeking = false));
  seek.addEventListener("input", () => {
    const t = Number(seek.value);
    if (state.ws) send({ op: "seek", time: t });
    else showPoseAt(t).catch(report);
  });
  $("speed").addEventListener("change", () => {
    const speed = Number($("speed").value);
    if (!state.ws) return;
    if (!Number.isFinite(speed)) return refusedControl(`speed must be a number, not "${$("speed").value}"`);
    // Sent either way, so that the server's own words explain a refusal;
    // kept only if it is one the server takes (docs/api.md: within ±1000).
    if (Math.abs(speed) <= 1000) state.speed = speed;
    send({ op: "speed", speed });
  });
  document.addEventListener("keydown", onKey);
  for (const id of ["fps", "playback", "space", "ease", "encoding"]) $(id).addEventListener("change", restartStream);
}
