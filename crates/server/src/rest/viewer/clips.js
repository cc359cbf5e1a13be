// The clip list: loaded page by page (library.js shows it); selecting a
// clip (its document, range, camera, first pose and curves), forgetting a
// deleted one, and adopting the clip a crossfade brought in.

import { api, listAll, savedToken } from "./api.js";
import { drawCurves, loadCurve, setupCurveSelectors } from "./curves.js";
import { $, dispatchStatus, setStatus } from "./dom.js";
import { emit } from "./events.js";
import { setEnded, showPoseAt, stopStream, updateReadout } from "./player.js";
import { fitCamera, requestDraw } from "./scene.js";
import { state } from "./state.js";

export async function loadClips() {
  state.clips = await listAll("/v1/clips", "clips");
  $("token-form").classList.remove("wanted");
  emit("listChanged");
}

/// Loads the list; a refusal says what to do about it.
export async function loadClipsOrExplain() {
  try {
    await loadClips();
  } catch (e) {
    const given = savedToken();
    const hint = $("token-form").classList.contains("wanted")
      ? given ? " — the token was refused; enter another" : " — this server needs a read token: enter it under Token"
      : "";
    setStatus(`listing clips: ${e.message}${hint}`, true);
  }
}

export async function selectClip(id) {
  stopStream();
  setEnded(false);
  const summary = state.clips.find((c) => c.id === id);
  const doc = await api(`/v1/clips/${encodeURIComponent(id)}`);
  Object.assign(state, { clip: summary, doc, names: [], frames: 0, seq: null, dropped: 0, latencyMs: null });
  emit("clipSelected", summary);
  state.requestTime = state.clipTime = summary.start;
  const seek = $("seek");
  seek.min = summary.start;
  seek.max = summary.end;
  seek.value = summary.start;
  seek.disabled = false;
  $("play").disabled = false;
  emit("listChanged");
  setupCurveSelectors();
  dispatchStatus({ type: "select", clip: summary });
  await Promise.all([fitCamera(), showPoseAt(summary.start), loadCurve()]);
  updateReadout();
}

/// Makes `id` the page's clip while its stream goes on (a crossfade
/// brought it in): its range, its place in the list, its curves.
export async function adoptClip(id) {
  const summary = state.clips.find((c) => c.id === id);
  if (!summary || state.clip?.id === id) return;
  const doc = await api(`/v1/clips/${encodeURIComponent(id)}`);
  Object.assign(state, { clip: summary, doc });
  dispatchStatus({ type: "adopt", clip: summary });
  emit("clipAdopted", summary);
  $("seek").min = summary.start;
  $("seek").max = summary.end;
  emit("listChanged");
  setupCurveSelectors();
  await loadCurve();
}

/// No clip shown any more (it was deleted): the stream stops, the view empties.
export function forgetClip() {
  stopStream();
  Object.assign(state, { clip: null, doc: null, names: [], parents: [], drawnJoints: [], positions: [], curve: null });
  $("play").disabled = true;
  $("seek").disabled = true;
  dispatchStatus({ type: "deselect" });
  drawCurves();
  requestDraw();
  emit("listChanged");
}
