// Where the page's live controls go — the stream's socket, or the watched
// broadcast's controls route (docs/broadcasts.md), where they act for every viewer —
// what a refusal does, and whether the controls are shown: a broadcast
// shows them only to a caller with the write scope.

import { api, authHeaders, describeProblem } from "./api.js";
import { $, setStatus } from "./dom.js";
import { emit } from "./events.js";
import { broadcast, state } from "./state.js";

/// A live control (`{op, …}`): to the broadcast watched, else to the stream.
export function send(control) {
  if (state.watching) return postControl(control);
  if (state.ws?.readyState === WebSocket.OPEN) state.ws.send(JSON.stringify(control));
}

/// The server refused a control (`{"error": problem}`): say so, and put
/// the speed box back to the speed still in force.
export function refusedControl(problem) {
  setStatus(`control refused: ${describeProblem(problem)}`, true);
  $("speed").value = state.speed;
  emit("refused", problem);
}

const path = (id) => `/v1/broadcasts/${encodeURIComponent(id)}`;

/// Controls a drag or a slider sends many of: while one is on its way,
/// only the latest of the same kind waits to follow it.
const COALESCED = new Set(["seek", "layer", "ik"]);
const inFlight = new Map(); // kind → the control waiting behind it (or null)

/// A control for every viewer of the broadcast. A refusal for want of scope hides the controls.
function postControl(body) {
  const kind = body.op === "layer" ? `layer ${body.index}` : body.op;
  if (COALESCED.has(body.op) && inFlight.has(kind)) return void inFlight.set(kind, body);
  if (COALESCED.has(body.op)) inFlight.set(kind, null);
  const id = broadcast.id;
  api(`${path(id)}/controls`, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) })
    .then(({ seq }) => (broadcast.lastControl = { op: body.op, seq }))
    .catch((e) => {
      refusedControl(e.message);
      if (broadcast.id === id) probeScope().catch((e) => setStatus(e.message, true));
    })
    .finally(() => {
      if (!COALESCED.has(body.op)) return;
      const next = inFlight.get(kind);
      inFlight.delete(kind);
      if (next && broadcast.id === id) postControl(next);
    });
}

/// Settings a broadcast fixed when it was created cannot change while watching.
const FIXED = ["fps", "playback", "space", "ease"];

/// The broadcast panel and the fixed settings as watching (or not) makes them.
export function showWatching() {
  const watching = Boolean(state.watching);
  for (const id of FIXED) $(id).disabled = watching;
  $("broadcast-leave").hidden = !watching;
  $("broadcast-copy").disabled = !watching;
  $("broadcast-link").value = watching ? broadcast.link : "";
  $("broadcast-info").textContent = watching
    ? `watching ${broadcast.id} at ${broadcast.summary.fps} fps${broadcast.canControl === false ? " (read only)" : ""}`
    : "";
  document.body.classList.toggle("watching", watching);
}

/// The controls: shown to a caller with the write scope only.
export function setControlsShown(shown) {
  const controls = [$("play"), $("seek"), $("speed").closest("label"), $("composition"), $("ik-panel"), $("broadcast")];
  for (const e of controls) if (e) e.hidden = !shown;
}

/// Asks the controls route with an empty body: 401/403 without the write
/// scope, else 400 (not JSON), which changes nothing.
export async function probeScope() {
  const id = broadcast.id;
  const response = await fetch(`${path(id)}/controls`, {
    method: "POST",
    headers: { ...authHeaders(), "Content-Type": "application/json" },
    body: "",
  });
  if (broadcast.id !== id) return;
  broadcast.canControl = response.status !== 401 && response.status !== 403;
  setControlsShown(broadcast.canControl);
  showWatching();
}
