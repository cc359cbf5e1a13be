// The viewer's broadcasts (issue 20, docs/broadcasts.md). "Broadcast" creates one from
// the current view (`POST /v1/broadcasts` with the page's motion — a graph
// with its settings and report — fps and space), shows a link to it (`/viewer?broadcast=ID`) and watches it; a
// page opened with that link watches it too (WebSocket
// `/v1/broadcasts/{id}/stream`). While watching, the page's controls (play,
// pause, seek, speed, layer weights, crossfades, IK handles) go to
// `POST /v1/broadcasts/{id}/controls` and act for every viewer (controls.js).
// They are shown only to a caller with the write scope: the page asks the
// controls route once with an empty body, which the server answers 401/403
// without that scope (and 400 with it, doing nothing). A refusal later
// hides them too.

import { api, postJson } from "./api.js";
import { loadClips, selectClip } from "./clips.js";
import { heldSettings, motion } from "./composition.js";
import { probeScope, send, setControlsShown, showWatching } from "./controls.js";
import { $, el, row, setStatus } from "./dom.js";
import { on } from "./events.js";
import { choose as chooseGraph } from "./graph.js";
import { adopt } from "./panel.js";
import { openStream, setPlaying, stopStream } from "./player.js";
import { fps, options } from "./settings.js";
import { broadcast, state } from "./state.js";

const RECENT_FRAMES = 240; // frames kept by seq, for comparing viewers

function build() {
  $("panel").append(
    el(
      "section",
      { id: "broadcast-panel" },
      el("h2", { textContent: "Broadcast" }),
      row(
        el("button", { id: "broadcast", type: "button", textContent: "Broadcast", title: "Share this view: one playback, any number of viewers" }),
        el("button", { id: "broadcast-leave", type: "button", textContent: "Leave", hidden: true }),
      ),
      row(
        el("input", { id: "broadcast-link", type: "text", readOnly: true, placeholder: "no broadcast", ariaLabel: "Link to the broadcast" }),
        el("button", { id: "broadcast-copy", type: "button", textContent: "Copy", disabled: true }),
      ),
      el("p", { id: "broadcast-info", className: "info" }),
    ),
  );
}

const report = (e) => setStatus(e.message, true);
const path = (id) => `/v1/broadcasts/${encodeURIComponent(id)}`;
const linkTo = (id) => `${location.origin}/viewer?broadcast=${encodeURIComponent(id)}`;

/// Creates a broadcast of what the page shows and watches it.
async function create() {
  if (!state.clip) return setStatus("select a clip to broadcast", true);
  const body = {
    motion: motion(),
    fps: fps(),
    space: options().space,
    ...(state.graph ? { report: true } : {}),
  };
  const summary = await postJson("/v1/broadcasts", body);
  await watch(summary.id, summary);
  // A graph broadcast starts from the graph's defaults: the page's settings follow.
  if (state.graph) send({ op: "set", parameters: heldSettings(state.graph.controls) });
  setStatus(`broadcasting ${summary.id}: anyone with the link watches the same frames`);
}

/// Watches the broadcast `id`: its clip (or graph) selected, its motion in
/// the panel, the page's stream its watch socket, the controls its controls route.
async function watch(id, known) {
  const summary = known || (await api(path(id)));
  const graph = summary.motion.layers.find((l) => l.graph)?.graph ?? "";
  leave({ quiet: true });
  broadcast.selecting = true;
  try {
    await (graph ? chooseGraph(graph, { quiet: true }) : showClip(summary.motion.layers[0].clip));
  } finally {
    broadcast.selecting = false;
  }
  adopt(summary.motion);
  Object.assign(broadcast, { id: summary.id, summary, link: linkTo(summary.id), canControl: null });
  broadcast.frames.clear();
  state.watching = summary.id; // controls.js sends the controls to the broadcast now
  history.replaceState(null, "", `/viewer?broadcast=${encodeURIComponent(summary.id)}`);
  $("fps").value = summary.fps;
  $("space").value = summary.space;
  showWatching();
  stopStream();
  if (openStream()) setPlaying(summary.state === "playing");
  await probeScope();
}

/// The broadcast's first clip as the page's clip, and no graph.
async function showClip(clip) {
  if (!state.clips.some((c) => c.id === clip)) await loadClips();
  if (state.clip?.id !== clip) await selectClip(clip);
  await chooseGraph("", { quiet: true });
}

/// Stops watching: the page is its own player again.
function leave({ quiet = false } = {}) {
  if (!state.watching) return;
  state.watching = null;
  broadcast.id = null;
  stopStream();
  history.replaceState(null, "", "/viewer");
  setControlsShown(true);
  showWatching();
  if (!quiet) setStatus("left the broadcast");
}

/// The frames received while watching, the latest RECENT_FRAMES by seq.
function record(frame) {
  if (!state.watching) return;
  broadcast.frames.set(frame.seq, frame.pose);
  if (broadcast.frames.size > RECENT_FRAMES) broadcast.frames.delete(broadcast.frames.keys().next().value);
}

async function copyLink() {
  const input = $("broadcast-link");
  try {
    await navigator.clipboard.writeText(input.value);
  } catch {
    input.select();
    document.execCommand("copy");
  }
  setStatus("link copied");
}

/// The panel; watches the broadcast of a `?broadcast=` link once the clip
/// list is `ready`.
export function setup(ready) {
  build();
  on("received", record);
  // Picking another clip leaves the broadcast.
  on("clipSelected", () => {
    if (state.watching && !broadcast.selecting) leave();
  });
  $("broadcast").addEventListener("click", () => create().catch(report));
  $("broadcast-leave").addEventListener("click", () => leave());
  $("broadcast-copy").addEventListener("click", () => copyLink().catch(report));
  $("broadcast-link").addEventListener("focus", (e) => e.target.select());
  const wanted = new URLSearchParams(location.search).get("broadcast");
  const open = () => (wanted && !state.watching ? watch(wanted) : Promise.resolve());
  // A token entered later (a read token to watch, a write token to control) is used at once.
  $("token-form").addEventListener("submit", () => {
    setTimeout(() => (state.watching ? probeScope() : ready.then(open)).catch(report), 0);
  });
  ready.then(open).catch((e) => setStatus(`broadcast ${wanted}: ${e.message}`, true));
}
