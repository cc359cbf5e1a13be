// The viewer's broadcasts (issue 20, SPEC §9). "Broadcast" creates one from
// the current view (`POST /v1/broadcasts` with the page's motion, fps and
// space), shows a link to it (`/viewer?broadcast=ID`) and watches it; a
// page opened with that link watches it too (WebSocket
// `/v1/broadcasts/{id}/stream`). While watching, the page's controls (play,
// pause, seek, speed, layer weights, crossfades, IK handles) go to
// `POST /v1/broadcasts/{id}/controls` and act for every viewer. They are
// shown only to a caller with the write scope: the page asks the controls
// route once with an empty body, which the server answers 401/403 without
// that scope (and 400 with it, doing nothing). A refusal later hides them too.
"use strict";

(() => {
  const viewer = window.inbetweenViewer;
  if (!viewer) return;
  const { state, hooks } = viewer;
  const $ = (id) => document.getElementById(id);
  const RECENT_FRAMES = 240; // frames kept by seq, for comparing viewers

  const broadcast = {
    id: null, // the broadcast watched
    summary: null, // its GET summary when the page started watching it
    canControl: null, // whether this caller may control it (null: not known yet)
    link: null,
    frames: new Map(), // seq → pose of the frames received while watching
  };
  viewer.broadcast = broadcast;

  function el(tag, props = {}, ...children) {
    const e = Object.assign(document.createElement(tag), props);
    e.append(...children);
    return e;
  }

  function build() {
    const row = (...children) => el("div", { className: "row" }, ...children);
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

  const report = (e) => viewer.setStatus(e.message, true);
  const path = (id) => `/v1/broadcasts/${encodeURIComponent(id)}`;
  const linkTo = (id) => `${location.origin}/viewer?broadcast=${encodeURIComponent(id)}`;

  /// Creates a broadcast of what the page shows and watches it.
  async function create() {
    if (!state.clip) return viewer.setStatus("select a clip to broadcast", true);
    const body = {
      motion: viewer.panel ? viewer.panel.motion() : { layers: [{ clip: state.clip.id }] },
      fps: Math.round(Number($("fps").value)) || 30,
      space: viewer.options().space,
    };
    const summary = await viewer.postJson("/v1/broadcasts", body);
    await watch(summary.id, summary);
    viewer.setStatus(`broadcasting ${summary.id}: anyone with the link watches the same frames`);
  }

  /// Watches the broadcast `id`: its clip selected, its motion in the panel,
  /// the page's stream its watch socket, the controls its controls route.
  async function watch(id, known) {
    const summary = known || (await viewer.api(path(id)));
    const first = summary.motion.layers[0].clip;
    leave({ quiet: true });
    if (!state.clips.some((c) => c.id === first)) await viewer.loadClips();
    if (state.clip?.id !== first) {
      broadcast.selecting = true;
      try {
        await viewer.selectClip(first);
      } finally {
        broadcast.selecting = false;
      }
    }
    viewer.panel?.adopt(summary.motion);
    Object.assign(broadcast, { id: summary.id, summary, link: linkTo(summary.id), canControl: null });
    broadcast.frames.clear();
    state.watching = summary.id;
    hooks.sendControl = control;
    history.replaceState(null, "", `/viewer?broadcast=${encodeURIComponent(summary.id)}`);
    $("fps").value = summary.fps;
    $("space").value = summary.space;
    showWatching();
    viewer.stopStream();
    if (viewer.openStream()) viewer.setPlaying(summary.state === "playing");
    await probeScope();
  }

  /// Stops watching: the page is its own player again.
  function leave({ quiet = false } = {}) {
    if (!state.watching) return;
    state.watching = null;
    hooks.sendControl = null;
    broadcast.id = null;
    viewer.stopStream();
    history.replaceState(null, "", "/viewer");
    setControlsShown(true);
    showWatching();
    if (!quiet) viewer.setStatus("left the broadcast");
  }

  /// Settings a broadcast fixed when it was created cannot change while watching.
  const FIXED = ["fps", "playback", "space", "ease"];

  function showWatching() {
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
  function setControlsShown(shown) {
    const controls = [$("play"), $("seek"), $("speed").closest("label"), $("composition"), $("ik-panel"), $("broadcast")];
    for (const e of controls) if (e) e.hidden = !shown;
  }

  /// Asks the controls route with an empty body: 401/403 without the write
  /// scope, else 400 (not JSON), which changes nothing.
  async function probeScope() {
    const id = broadcast.id;
    const response = await fetch(`${path(id)}/controls`, {
      method: "POST",
      headers: { ...viewer.authHeaders(), "Content-Type": "application/json" },
      body: "",
    });
    if (broadcast.id !== id) return;
    broadcast.canControl = response.status !== 401 && response.status !== 403;
    setControlsShown(broadcast.canControl);
    showWatching();
  }

  /// Controls a drag or a slider sends many of: while one is on its way,
  /// only the latest of the same kind waits to follow it.
  const COALESCED = new Set(["seek", "layer", "ik"]);
  const inFlight = new Map(); // kind → the control waiting behind it (or null)

  /// A control for every viewer. A refusal for want of scope hides the controls.
  function control(body) {
    const kind = body.op === "layer" ? `layer ${body.index}` : body.op;
    if (COALESCED.has(body.op) && inFlight.has(kind)) return void inFlight.set(kind, body);
    if (COALESCED.has(body.op)) inFlight.set(kind, null);
    const id = broadcast.id;
    viewer
      .api(`${path(id)}/controls`, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) })
      .then(({ seq }) => (broadcast.lastControl = { op: body.op, seq }))
      .catch((e) => {
        viewer.refusedControl(e.message);
        if (broadcast.id === id) probeScope().catch(report);
      })
      .finally(() => {
        if (!COALESCED.has(body.op)) return;
        const next = inFlight.get(kind);
        inFlight.delete(kind);
        if (next && broadcast.id === id) control(next);
      });
  }

  /// The watch socket, instead of the page's own stream.
  const composed = hooks.streamTarget;
  hooks.streamTarget = () => {
    if (!state.watching) return composed ? composed() : null;
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    return { url: `${scheme}://${location.host}${path(state.watching)}/stream` };
  };

  hooks.frame.push((frame) => {
    if (!state.watching) return;
    broadcast.frames.set(frame.seq, frame.pose);
    if (broadcast.frames.size > RECENT_FRAMES) broadcast.frames.delete(broadcast.frames.keys().next().value);
  });

  // Picking another clip leaves the broadcast.
  hooks.clipSelected.push(() => {
    if (state.watching && !broadcast.selecting) leave();
  });

  async function copyLink() {
    const input = $("broadcast-link");
    try {
      await navigator.clipboard.writeText(input.value);
    } catch {
      input.select();
      document.execCommand("copy");
    }
    viewer.setStatus("link copied");
  }

  function setup() {
    build();
    $("broadcast").addEventListener("click", () => create().catch(report));
    $("broadcast-leave").addEventListener("click", () => leave());
    $("broadcast-copy").addEventListener("click", () => copyLink().catch(report));
    $("broadcast-link").addEventListener("focus", (e) => e.target.select());
    const wanted = new URLSearchParams(location.search).get("broadcast");
    const open = () => (wanted && !state.watching ? watch(wanted) : Promise.resolve());
    // A token entered later (a read token to watch, a write token to control) is used at once.
    $("token-form").addEventListener("submit", () => {
      setTimeout(() => (state.watching ? probeScope() : viewer.ready.then(open)).catch(report), 0);
    });
    viewer.ready.then(open).catch((e) => viewer.setStatus(`broadcast ${wanted}: ${e.message}`, true));
  }

  setup();
})();
