// The clip list: loaded page by page, filtered by name; selecting a clip
// (its document, range, camera, first pose and curves), and adopting the
// clip a crossfade brought in.

import { api, savedToken } from "./api.js";
import { loadCurve, setupCurveSelectors } from "./curves.js";
import { $, setStatus } from "./dom.js";
import { emit } from "./events.js";
import { setEnded, showPoseAt, stopStream, updateReadout } from "./player.js";
import { fitCamera } from "./scene.js";
import { state } from "./state.js";

export async function loadClips() {
  const clips = [];
  let cursor = null;
  for (let page = 0; page < 20; page++) {
    const q = cursor ? `&cursor=${encodeURIComponent(cursor)}` : "";
    const body = await api(`/v1/clips?limit=500${q}`);
    clips.push(...body.clips);
    cursor = body.next_cursor;
    if (!cursor) break;
  }
  state.clips = clips;
  $("token-form").classList.remove("wanted");
  renderClips();
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

function renderClips() {
  const needle = $("filter").value.trim().toLowerCase();
  const list = $("clips");
  list.replaceChildren();
  for (const c of state.clips) {
    if (needle && !c.name.toLowerCase().includes(needle)) continue;
    const li = document.createElement("li");
    li.dataset.id = c.id;
    li.textContent = c.name;
    const small = document.createElement("small");
    small.textContent = `${c.joints} joints · ${c.tracks} tracks · ${c.duration.toFixed(2)} s`;
    li.append(small);
    li.classList.toggle("selected", state.clip?.id === c.id);
    li.addEventListener("click", () => selectClip(c.id).catch((e) => setStatus(e.message, true)));
    list.append(li);
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
  renderClips();
  setupCurveSelectors();
  await Promise.all([fitCamera(), showPoseAt(summary.start), loadCurve()]);
  updateReadout();
  setStatus(`${summary.name}: ${summary.joints} joints, ${summary.start}–${summary.end} s`);
}

/// Makes `id` the page's clip while its stream goes on (a crossfade
/// brought it in): its range, its place in the list, its curves.
export async function adoptClip(id) {
  const summary = state.clips.find((c) => c.id === id);
  if (!summary || state.clip?.id === id) return;
  const doc = await api(`/v1/clips/${encodeURIComponent(id)}`);
  Object.assign(state, { clip: summary, doc });
  emit("clipAdopted", summary);
  $("seek").min = summary.start;
  $("seek").max = summary.end;
  renderClips();
  setupCurveSelectors();
  await loadCurve();
}

export function setup() {
  $("filter").addEventListener("input", renderClips);
}
