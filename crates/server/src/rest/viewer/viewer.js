// The inbetween viewer: lists clips, plays a clip's WebSocket stream as a
// 3D skeleton on a <canvas> (a small hand-written projection, no library),
// and plots one channel's sampled curve with its keys. It talks only to the
// REST API and the stream of the server that served it.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  const TOKEN_KEY = "inbetween.token";
  const CURVE_POINTS = 400; // samples per plotted curve, at most
  const FIT_POINTS = 30; // model-space poses sampled to fit the camera
  const COLORS = ["#ff5c5c", "#5cd65c", "#5c9dff", "#c8c8c8", "#e0a040", "#c070e0"]; // x, y, z, w, then more parameter components

  const state = {
    clips: [],
    clip: null, // the selected clip's summary
    doc: null, // its document (skeleton, tracks)
    names: [], // joint names in pose order
    parents: [], // parent index per joint, -1 for roots
    drawnJoints: [], // per joint: drawn (a joint, not a placement node)
    positions: [], // model-space joint positions to draw
    ws: null,
    playing: false,
    ended: false, // a `once` stream reached its end: Play starts it over
    firstClipTime: null, // the clip time of the running stream's first frame
    speed: 1, // the running stream's speed (the last one the server took)
    requestTime: 0, // request time of the pose shown
    clipTime: 0, // its clip time (after playback and ease)
    poseAsked: 0, // paused poses asked for: only the newest one's answer is shown
    frames: 0,
    seq: null,
    dropped: 0,
    latencyMs: null,
    camera: { yaw: 0.7, pitch: 0.35, dist: 5, target: [0, 1, 0], radius: 1 },
    curve: null, // the plotted series (read by the browser test)
    pendingUpload: null,
    watching: null, // the broadcast this page watches (broadcast.js), if any
  };
  // Hooks for the page's other scripts (panel.js: composition and IK;
  // broadcast.js: broadcasts), so that they live in files of their own.
  const hooks = {
    streamTarget: null, // () => {url, open?}: what a new stream connects to (default: the clip route)
    sendControl: null, // (control) => void: where controls go (default: the stream's socket)
    poseAt: null, // (t) => Promise<pose> | null: the paused view's pose (default: the clip's GET pose)
    frame: [], // (frame) => void, per stream frame
    pose: [], // (pose) => void, after a pose is applied (may move state.positions)
    overlay: [], // (ctx, cam, dpr) => void, after the scene is drawn
    clipSelected: [], // (clip) => void, after a clip is selected
    clipAdopted: [], // (clip) => void, after a crossfade made its clip the page's
    refused: [], // (problem) => void, when the server refuses a control
  };
  const viewer = { state, hooks, cspViolations: [] };
  window.inbetweenViewer = viewer;
  document.addEventListener("securitypolicyviolation", (e) =>
    viewer.cspViolations.push(`${e.violatedDirective} ${e.blockedURI}`),
  );

  // ---- REST helpers ----

  function authHeaders() {
    const token = sessionStorage.getItem(TOKEN_KEY);
    return token ? { Authorization: `Bearer ${token}` } : {};
  }

  /// A problem document (SPEC §3) as one line: its detail, then its code
  /// and where (`pointer` or `parameter`). Never "[object Object]".
  function describeProblem(p, status) {
    if (typeof p === "string") return p;
    if (!p || typeof p !== "object") return `HTTP ${status ?? "error"}`;
    const what = p.detail || p.title || JSON.stringify(p);
    const where = p.pointer || p.parameter;
    const code = [p.code, status ?? p.status].filter((x) => x != null).join(", ");
    return `${what}${code ? ` (${code}${where ? ` at ${where}` : ""})` : ""}`;
  }

  async function problemText(response) {
    const text = await response.text().catch(() => "");
    try {
      return describeProblem(JSON.parse(text), response.status);
    } catch {
      return `HTTP ${response.status}${text ? `: ${text.slice(0, 200)}` : ""}`;
    }
  }

  /// `fetch`, with the request named when the network fails.
  async function request(path, options) {
    try {
      return await fetch(path, options);
    } catch (e) {
      throw new Error(`${options.method || "GET"} ${path}: ${e.message}`);
    }
  }

  async function api(path, options = {}) {
    const headers = { ...authHeaders(), ...(options.headers || {}) };
    const response = await request(path, { ...options, headers });
    if (response.status === 401) wantToken();
    if (!response.ok) throw new Error(await problemText(response));
    return response.json();
  }

  /// Points at the token field: the server wants a (different) token.
  function wantToken() {
    $("token-form").classList.add("wanted");
    $("token").focus();
  }

  const postJson = (path, body) =>
    api(path, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });

  function setStatus(text, isError = false) {
    const s = $("status");
    s.textContent = text;
    s.classList.toggle("error", isError);
  }

  // ---- clip list ----

  async function loadClips() {
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
  async function loadClipsOrExplain() {
    try {
      await loadClips();
    } catch (e) {
      const given = sessionStorage.getItem(TOKEN_KEY);
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

  async function selectClip(id) {
    stopStream();
    setEnded(false);
    const summary = state.clips.find((c) => c.id === id);
    const doc = await api(`/v1/clips/${encodeURIComponent(id)}`);
    Object.assign(state, { clip: summary, doc, names: [], frames: 0, seq: null, dropped: 0, latencyMs: null });
    for (const hook of hooks.clipSelected) hook(summary);
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
  async function adoptClip(id) {
    const summary = state.clips.find((c) => c.id === id);
    if (!summary || state.clip?.id === id) return;
    const doc = await api(`/v1/clips/${encodeURIComponent(id)}`);
    Object.assign(state, { clip: summary, doc });
    for (const hook of hooks.clipAdopted) hook(summary);
    $("seek").min = summary.start;
    $("seek").max = summary.end;
    renderClips();
    setupCurveSelectors();
    await loadCurve();
  }

  // ---- poses and the skeleton ----

  function parentsOf(names) {
    const joints = state.doc?.skeleton?.joints || [];
    const parentName = new Map(joints.map((j) => [j.name, j.parent]));
    const index = new Map(names.map((n, i) => [n, i]));
    return names.map((n) => (parentName.get(n) == null ? -1 : index.get(parentName.get(n)) ?? -1));
  }

  /// Which joints the view draws. A glTF skin's joints carry `inverse_bind`;
  /// when a clip has any, nodes without one (the scene root, an armature
  /// node) are not joints. Nor is the *placement* chain at the top of each
  /// tree: nodes without tracks, each with one child, whose ancestors are
  /// placement too — the Fox's `root → _rootJoint → b_Root_00`, unweighted
  /// nodes at the floor origin that only place the rig; drawing them gave a
  /// stray bone from the floor to the hip. A bone is drawn from a drawn
  /// joint to a drawn child.
  function drawnJoints(names, parents) {
    const joints = new Map((state.doc?.skeleton?.joints || []).map((j) => [j.name, j]));
    const skinned = [...joints.values()].some((j) => j.inverse_bind);
    const animated = new Set((state.doc?.tracks || []).map((t) => t.joint));
    const children = names.map(() => 0);
    parents.forEach((p) => p >= 0 && (children[p] += 1));
    const placement = [];
    names.forEach((n, i) => {
      const p = parents[i];
      placement[i] = !animated.has(n) && children[i] <= 1 && (p < 0 || placement[p]);
    });
    return names.map((n, i) => !placement[i] && (!skinned || Boolean(joints.get(n)?.inverse_bind)));
  }

  function rotate(q, v) {
    // v + 2w(q×v) + 2q×(q×v), q = [x, y, z, w]
    const [x, y, z, w] = q;
    const cx = y * v[2] - z * v[1], cy = z * v[0] - x * v[2], cz = x * v[1] - y * v[0];
    const dx = y * cz - z * cy, dy = z * cx - x * cz, dz = x * cy - y * cx;
    return [v[0] + 2 * (w * cx + dx), v[1] + 2 * (w * cy + dy), v[2] + 2 * (w * cz + dz)];
  }

  function qmul(a, b) {
    const [ax, ay, az, aw] = a, [bx, by, bz, bw] = b;
    return [
      aw * bx + ax * bw + ay * bz - az * by,
      aw * by - ax * bz + ay * bw + az * bx,
      aw * bz + ax * by - ay * bx + az * bw,
      aw * bw - ax * bx - ay * by - az * bz,
    ];
  }

  /// Model-space positions from a pose: as sent for `space=model`, else
  /// composed down the hierarchy here (SPEC §2.8).
  function modelPositions(pose) {
    const joints = pose.joints;
    if (pose.space === "model") return joints.map((j) => j.translation);
    const model = [];
    joints.forEach((j, i) => {
      const p = state.parents[i];
      if (p < 0 || p >= i) {
        model.push({ t: j.translation, q: j.rotation, s: j.scale });
        return;
      }
      const m = model[p];
      const scaled = [m.s[0] * j.translation[0], m.s[1] * j.translation[1], m.s[2] * j.translation[2]];
      const r = rotate(m.q, scaled);
      model.push({
        t: [m.t[0] + r[0], m.t[1] + r[1], m.t[2] + r[2]],
        q: qmul(m.q, j.rotation),
        s: [m.s[0] * j.scale[0], m.s[1] * j.scale[1], m.s[2] * j.scale[2]],
      });
    });
    return model.map((m) => m.t);
  }

  function applyPose(pose) {
    const names = pose.joints.map((j) => j.name);
    if (names.join("\n") !== state.names.join("\n")) {
      state.names = names;
      state.parents = parentsOf(names);
      state.drawnJoints = drawnJoints(names, state.parents);
    }
    state.positions = modelPositions(pose);
    state.requestTime = pose.time;
    state.clipTime = pose.clip_time;
    for (const hook of hooks.pose) hook(pose);
    requestDraw();
  }

  function options() {
    const o = { space: $("space").value, ease: $("ease").value };
    if ($("playback").value) o.playback = $("playback").value;
    return o;
  }

  /// Shows the pose at `t`. Answers can arrive out of order (the browser
  /// spreads requests over connections), so only the newest request's answer
  /// is shown, and none once a stream has opened since.
  async function showPoseAt(t) {
    const asked = ++state.poseAsked;
    const q = new URLSearchParams({ t: String(t), ...options() });
    const composed = hooks.poseAt?.(t);
    const pose = await (composed || api(`/v1/clips/${encodeURIComponent(state.clip.id)}/pose?${q}`));
    if (asked !== state.poseAsked) return;
    applyPose(pose);
    updateReadout();
  }

  // ---- the stream ----

  function streamUrl() {
    const q = new URLSearchParams({
      fps: String(Math.round(Number($("fps").value)) || 30),
      speed: String(Number($("speed").value) || 1),
      start: String(state.requestTime),
      ...options(),
    });
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    return `${scheme}://${location.host}/v1/clips/${encodeURIComponent(state.clip.id)}/stream?${q}`;
  }

  /// The subprotocols that carry the token: a browser cannot set headers on
  /// a WebSocket, so it offers `inbetween.bearer.<base64url of the token>`
  /// next to `inbetween`, which the server selects (README, Security).
  function streamProtocols() {
    const token = sessionStorage.getItem(TOKEN_KEY);
    if (!token) return [];
    const bytes = new TextEncoder().encode(token);
    const b64 = btoa(String.fromCharCode(...bytes)).replace(/\+/g, "-").replace(/\//g, "_").replace(/=+$/, "");
    return ["inbetween", `inbetween.bearer.${b64}`];
  }

  /// What the page can check itself before opening a stream (the server
  /// refuses a bad handshake with a body the WebSocket API cannot read).
  function streamSettingsProblem() {
    const fps = Number($("fps").value), speed = Number($("speed").value);
    if (!(Number.isInteger(fps) && fps >= 1 && fps <= 240)) return `fps must be a whole number from 1 to 240, not "${$("fps").value}"`;
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

  function openStream() {
    const settings = streamSettingsProblem();
    if (settings) {
      setStatus(settings, true);
      return false;
    }
    const target = hooks.streamTarget?.() || { url: streamUrl() };
    const ws = new WebSocket(target.url, streamProtocols());
    state.poseAsked += 1; // a paused pose still on its way is older than the stream
    if (target.open) ws.onopen = () => ws.send(JSON.stringify(target.open));
    state.ws = ws;
    state.speed = Number($("speed").value) || 1;
    setEnded(false);
    // The readout counts this stream's ticks: each frame's `dropped` is the
    // ticks skipped since the previous frame, so the total is their sum.
    Object.assign(state, { frames: 0, seq: null, dropped: 0 });
    ws.onmessage = (message) => {
      if (typeof message.data !== "string") return;
      const frame = JSON.parse(message.data);
      if (frame.opened) return;
      if (frame.error && target.open && !state.frames) return setStatus(`stream refused: ${describeProblem(frame.error)}`, true);
      if (frame.error) return refusedControl(frame.error);
      const nowNanos = (performance.timeOrigin + performance.now()) * 1e6;
      state.frames += 1;
      if (state.frames === 1) state.firstClipTime = frame.clip_time;
      state.seq = frame.seq;
      state.dropped += frame.dropped;
      state.latencyMs = (nowNanos - frame.sent_at_unix_nanos) / 1e6;
      if (frame.events?.length) setStatus(`event: ${frame.events.map((e) => e.name).join(", ")}`);
      applyPose(frame.pose);
      for (const hook of hooks.frame) hook(frame);
      updateReadout();
      if (state.playing && reachedEnd(frame.clip_time)) endOnce();
    };
    ws.onclose = (e) => {
      if (state.ws !== ws) return;
      state.ws = null;
      setPlaying(false);
      if (!state.frames && e.code === 1006) explainRefusedStream(e);
      else if (e.code !== 1000 && e.code !== 1005) setStatus(`stream closed (${e.code}) ${e.reason}`, true);
    };
    return true;
  }

  /// The server refused a control (`{"error": problem}`): say so, and put
  /// the speed box back to the speed still in force.
  function refusedControl(problem) {
    setStatus(`control refused: ${describeProblem(problem)}`, true);
    $("speed").value = state.speed;
    for (const hook of hooks.refused) hook(problem);
  }

  /// The playback mode in force: the page's choice, else the clip's default.
  const playbackMode = () => $("playback").value || state.clip?.playback || "loop";

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
    setStatus(`${state.clip.name} ended at ${state.clipTime.toFixed(3)} s — Play starts it over`);
  }

  function setEnded(ended) {
    state.ended = ended;
    $("play").classList.toggle("ended", ended);
    $("play").title = ended ? "Ended: play again from the start" : "";
  }

  function send(control) {
    if (hooks.sendControl) return hooks.sendControl(control);
    if (state.ws?.readyState === WebSocket.OPEN) state.ws.send(JSON.stringify(control));
  }

  function stopStream() {
    const ws = state.ws;
    state.ws = null;
    state.playing = false;
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

  function setPlaying(playing) {
    state.playing = playing;
    $("play").textContent = playing ? "Pause" : "Play";
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
    const fps = Math.round(Number($("fps").value)) || 30;
    const here = Number($("seek").value);
    const step = e.shiftKey ? 1 : 1 / fps;
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

  function updateReadout() {
    $("seq").textContent = state.seq ?? "–";
    $("clip-time").textContent = `${state.clipTime.toFixed(3)} s`;
    $("dropped").textContent = state.seq == null ? "–" : state.dropped;
    $("latency").textContent = state.latencyMs == null ? "–" : `${state.latencyMs.toFixed(1)} ms`;
    $("frames").textContent = state.frames;
    if (!viewer.seeking) $("seek").value = requestTimeOf(state.clipTime);
    drawCurves();
  }

  // ---- ease: clip time back to request time, for the seek bar and plots ----

  const EASES = {
    linear: (x) => x,
    ease_in: (x) => x * x,
    ease_out: (x) => 1 - (1 - x) * (1 - x),
    ease_in_out: (x) => 3 * x * x - 2 * x * x * x,
  };

  /// The request time in the clip's range whose eased clip time is `clipTime`
  /// (each ease is increasing, so bisection finds it).
  function requestTimeOf(clipTime) {
    const { start, end } = state.clip || { start: 0, end: 0 };
    const ease = EASES[$("ease").value];
    if (end <= start || ease === EASES.linear) return clipTime;
    const y = Math.min(1, Math.max(0, (clipTime - start) / (end - start)));
    let lo = 0, hi = 1;
    for (let i = 0; i < 40; i++) {
      const mid = (lo + hi) / 2;
      if (ease(mid) < y) lo = mid;
      else hi = mid;
    }
    return start + ((lo + hi) / 2) * (end - start);
  }

  // ---- 3D view ----

  let drawQueued = false;
  function requestDraw() {
    if (drawQueued) return;
    drawQueued = true;
    requestAnimationFrame(() => {
      drawQueued = false;
      drawScene();
    });
  }

  /// Sizes a canvas's pixels to its box (the layout gives it the height the
  /// controls leave, so the page fits one screen).
  function sizeCanvas(canvas) {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
    }
    return dpr;
  }

  function cameraBasis(c, width, height) {
    const { yaw, pitch, dist, target } = state.camera;
    const eye = [
      target[0] + dist * Math.cos(pitch) * Math.sin(yaw),
      target[1] + dist * Math.sin(pitch),
      target[2] + dist * Math.cos(pitch) * Math.cos(yaw),
    ];
    const f = normalize(sub(target, eye));
    const r = normalize(cross(f, [0, 1, 0]));
    const u = cross(r, f);
    const focal = height / (2 * Math.tan((45 * Math.PI) / 360));
    const near = dist * 1e-3;
    return { eye, f, r, u, focal, near, cx: width / 2, cy: height / 2 };
  }

  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const normalize = (a) => {
    const n = Math.hypot(a[0], a[1], a[2]) || 1;
    return [a[0] / n, a[1] / n, a[2] / n];
  };

  const toCamera = (cam, p) => {
    const d = sub(p, cam.eye);
    return [dot(d, cam.r), dot(d, cam.u), dot(d, cam.f)];
  };
  const toScreen = (cam, v) => [cam.cx + (v[0] / v[2]) * cam.focal, cam.cy - (v[1] / v[2]) * cam.focal];

  /// A world-space segment, clipped at the near plane.
  function line(ctx, cam, a, b) {
    let p = toCamera(cam, a), q = toCamera(cam, b);
    if (p[2] < cam.near && q[2] < cam.near) return;
    if (p[2] < cam.near || q[2] < cam.near) {
      const k = (cam.near - p[2]) / (q[2] - p[2]);
      const cut = [p[0] + k * (q[0] - p[0]), p[1] + k * (q[1] - p[1]), cam.near];
      if (p[2] < cam.near) p = cut;
      else q = cut;
    }
    const [x0, y0] = toScreen(cam, p), [x1, y1] = toScreen(cam, q);
    ctx.moveTo(x0, y0);
    ctx.lineTo(x1, y1);
  }

  function stroke(ctx, color, width, build) {
    ctx.beginPath();
    build();
    ctx.strokeStyle = color;
    ctx.lineWidth = width;
    ctx.stroke();
  }

  /// The floor grid and the axes at the origin, as world-space segments by
  /// colour (RGBA 0–1 for mesh.js's WebGL, the CSS colour for the canvas).
  function groundLines() {
    const { target, radius } = state.camera;
    const step = 10 ** Math.floor(Math.log10(radius)) / 2;
    const n = Math.ceil((2 * radius) / step);
    const ox = Math.round(target[0] / step) * step, oz = Math.round(target[2] / step) * step;
    const grid = [];
    for (let i = -n; i <= n; i++) {
      grid.push([[ox + i * step, 0, oz - n * step], [ox + i * step, 0, oz + n * step]]);
      grid.push([[ox - n * step, 0, oz + i * step], [ox + n * step, 0, oz + i * step]]);
    }
    const rgba = (css) => [1, 3, 5].map((k) => parseInt(css.slice(k, k + 2), 16) / 255).concat(1);
    const axis = 2 * step;
    const axes = [[axis, 0, 0], [0, axis, 0], [0, 0, axis]].map((end, i) => ({
      css: COLORS[i], color: rgba(COLORS[i]), width: 2, segments: [[[0, 0, 0], end]],
    }));
    return [{ css: "#323846", color: rgba("#323846"), width: 1, segments: grid }, ...axes];
  }

  function drawScene() {
    const canvas = $("scene");
    const dpr = sizeCanvas(canvas);
    const ctx = canvas.getContext("2d");
    const cam = cameraBasis(canvas, canvas.width, canvas.height);
    const lines = groundLines();
    // With a skinned mesh, mesh.js draws background, ground and mesh below; this canvas only the skeleton.
    const mesh = viewer.mesh?.draw(cam, canvas.width, canvas.height, lines);
    if (mesh) ctx.clearRect(0, 0, canvas.width, canvas.height);
    else {
      ctx.fillStyle = "#101216";
      ctx.fillRect(0, 0, canvas.width, canvas.height);
      for (const { css, width, segments } of lines)
        stroke(ctx, css, width * dpr, () => segments.forEach(([a, b]) => line(ctx, cam, a, b)));
    }
    if (!mesh || viewer.mesh.showSkeleton) drawSkeleton(ctx, cam);
    else viewer.drawn = { bones: [], joints: 0 };
    for (const hook of hooks.overlay) hook(ctx, cam, dpr);
  }

  // ---- the skeleton as solids: octahedral bones and shaded joint spheres,
  // drawn far to near (painter's algorithm) on the 2D canvas ----

  const BONE_RGB = [200, 208, 220];
  const JOINT_COLOR = "#ff8c1a";

  /// The bones and joints to draw this frame, and their world sizes: the
  /// sphere radius and bone width follow the median bone length, bounded by
  /// the framed size so that neither vanishes nor swamps the view.
  function skeletonItems() {
    const pos = state.positions, drawn = state.drawnJoints || [];
    const bones = [];
    state.parents.forEach((p, i) => {
      if (p >= 0 && drawn[p] && drawn[i] && pos[p] && pos[i]) bones.push([p, i]);
    });
    const lengths = bones.map(([p, i]) => Math.hypot(...sub(pos[i], pos[p]))).filter((l) => l > 0).sort((a, b) => a - b);
    const median = lengths.length ? lengths[lengths.length >> 1] : state.camera.radius * 0.2;
    const R = state.camera.radius;
    const radius = Math.min(0.04 * R, Math.max(0.008 * R, 0.12 * median));
    const joints = pos.map((_, i) => i).filter((i) => drawn[i] && pos[i]);
    return { pos, bones, joints, radius };
  }

  /// The 8 faces of an octahedral bone from `a` to `b`: a square ring a fifth
  /// of the way along, pointed at both ends.
  function boneFaces(a, b, width) {
    const d = sub(b, a);
    const len = Math.hypot(...d);
    if (len < 1e-9) return [];
    const axis = [d[0] / len, d[1] / len, d[2] / len];
    const helper = Math.abs(axis[1]) < 0.9 ? [0, 1, 0] : [1, 0, 0];
    const u = normalize(cross(axis, helper)), v = cross(axis, u);
    const w = Math.min(width, 0.15 * len);
    const c = [a[0] + 0.2 * d[0], a[1] + 0.2 * d[1], a[2] + 0.2 * d[2]];
    const ring = [u, v, u.map((x) => -x), v.map((x) => -x)].map((e) => [c[0] + w * e[0], c[1] + w * e[1], c[2] + w * e[2]]);
    const faces = [];
    for (let k = 0; k < 4; k++) {
      const r0 = ring[k], r1 = ring[(k + 1) % 4];
      faces.push([a, r1, r0], [b, r0, r1]);
    }
    return faces;
  }

  function drawSkeleton(ctx, cam) {
    const { pos, bones, joints, radius } = skeletonItems();
    const light = normalize([cam.u[0] * 0.6 - cam.r[0] * 0.4 - cam.f[0], cam.u[1] * 0.6 - cam.r[1] * 0.4 - cam.f[1], cam.u[2] * 0.6 - cam.r[2] * 0.4 - cam.f[2]]);
    const items = [];
    for (const [p, i] of bones)
      for (const face of boneFaces(pos[p], pos[i], 1.6 * radius)) {
        const n = normalize(cross(sub(face[1], face[0]), sub(face[2], face[0])));
        if (dot(n, sub(face[0], cam.eye)) >= 0) continue; // facing away
        const v = face.map((q) => toCamera(cam, q));
        if (v.some((q) => q[2] < cam.near)) continue;
        const shade = 0.35 + 0.65 * Math.max(0, dot(n, light));
        items.push({ depth: (v[0][2] + v[1][2] + v[2][2]) / 3, face: v.map((q) => toScreen(cam, q)), shade });
      }
    for (const i of joints) {
      const v = toCamera(cam, pos[i]);
      if (v[2] < cam.near * 2) continue;
      items.push({ depth: v[2] - radius, center: toScreen(cam, v), r: (radius * cam.focal) / v[2] });
    }
    items.sort((a, b) => b.depth - a.depth);
    for (const item of items) (item.face ? drawFace : drawSphere)(ctx, item);
    viewer.drawn = { bones: bones.map(([p, i]) => [state.names[p], state.names[i]]), joints: joints.length };
  }

  function drawFace(ctx, { face, shade }) {
    ctx.beginPath();
    ctx.moveTo(face[0][0], face[0][1]);
    ctx.lineTo(face[1][0], face[1][1]);
    ctx.lineTo(face[2][0], face[2][1]);
    ctx.closePath();
    const [r, g, b] = BONE_RGB.map((c) => Math.round(c * shade));
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.strokeStyle = ctx.fillStyle; // closes the hairline seams between faces
    ctx.lineWidth = 0.5;
    ctx.fill();
    ctx.stroke();
  }

  /// A lit sphere: a radial gradient with its highlight up and to the left.
  function drawSphere(ctx, { center: [x, y], r }) {
    const g = ctx.createRadialGradient(x - 0.35 * r, y - 0.35 * r, 0.1 * r, x, y, r);
    g.addColorStop(0, "#ffd0a0");
    g.addColorStop(0.45, JOINT_COLOR);
    g.addColorStop(1, "#a04f00");
    ctx.fillStyle = g;
    ctx.beginPath();
    ctx.arc(x, y, Math.max(r, 1.5), 0, 2 * Math.PI);
    ctx.fill();
  }

  /// Frames the clip: the bounds of its model-space poses over its range.
  async function fitCamera() {
    const { id, start, end } = state.clip;
    const fps = end > start ? Math.min(240, Math.max(1, FIT_POINTS / (end - start))) : 1;
    const { poses } = await postJson(`/v1/clips/${encodeURIComponent(id)}/sample`, {
      start, end, fps, space: "model", playback: "once",
    });
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const pose of poses)
      for (const j of pose.joints)
        for (let k = 0; k < 3; k++) {
          lo[k] = Math.min(lo[k], j.translation[k]);
          hi[k] = Math.max(hi[k], j.translation[k]);
        }
    if (!(lo[0] <= hi[0])) return;
    const cam = state.camera;
    cam.target = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2];
    cam.radius = Math.max(Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2, 1e-3);
    cam.dist = cam.radius * 2.8;
    requestDraw();
  }

  function setupOrbit() {
    const canvas = $("scene");
    let drag = null;
    canvas.addEventListener("pointerdown", (e) => {
      drag = { x: e.clientX, y: e.clientY };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const cam = state.camera;
      cam.yaw -= (e.clientX - drag.x) * 0.01;
      cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + (e.clientY - drag.y) * 0.01));
      drag = { x: e.clientX, y: e.clientY };
      requestDraw();
    });
    canvas.addEventListener("pointerup", () => (drag = null));
    canvas.addEventListener(
      "wheel",
      (e) => {
        e.preventDefault();
        state.camera.dist *= Math.exp(e.deltaY * 0.001);
        requestDraw();
      },
      { passive: false },
    );
    canvas.addEventListener("dblclick", () => state.clip && fitCamera());
  }

  // ---- curves ----
  // A joint's channel or a parameter (SPEC §8), sampled by the server; a
  // rotation as Euler angles in a chosen order or as quaternion components;
  // keys marked, and the tangents of cubic Hermite keys drawn as handles.

  const PARAM = "param:"; // the curve selector's prefix for parameters

  function setupCurveSelectors() {
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

  async function loadCurve() {
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
    viewer.curve = state.curve;
    drawCurves();
  }

  /// A cubic Hermite track's tangents as Bezier handles (units per second
  /// times a third of the segment): out of key i at `t_i + h_i/3`, into key
  /// i at `t_i - h_{i-1}/3`, as SPEC §2.5's segment is that Bezier.
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

  /// Euler angles in degrees, `[x, y, z]`, of the unit quaternion `[x, y, z,
  /// w]` for `order` ("XYZ": X applied first, R = Rz·Ry·Rx).
  function eulerDegrees(q, order) {
    const [x, y, z, w] = q;
    const n = Math.hypot(x, y, z, w) || 1;
    const [qx, qy, qz, qw] = [x / n, y / n, z / n, w / n];
    const R = [
      [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
      [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
      [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ];
    const [i, j, k] = [...order].map((c) => "XYZ".indexOf(c));
    const s = (j - i + 3) % 3 === 1 ? 1 : -1; // +1 for the cyclic orders
    const out = [0, 0, 0];
    out[i] = Math.atan2(s * R[k][j], R[k][k]);
    out[j] = Math.asin(Math.max(-1, Math.min(1, -s * R[k][i])));
    out[k] = Math.atan2(s * R[j][i], R[i][i]);
    return out.map((r) => (r * 180) / Math.PI);
  }

  /// `a` with whole turns added to each angle to be nearest `b`.
  const nearestBranch = (a, b) => a.map((v, c) => v + 360 * Math.round((b[c] - v) / 360));

  /// Angles made continuous along the series (no ±180° jumps).
  function unwrapSeries(series) {
    const out = [];
    for (const v of series) out.push(out.length ? nearestBranch(v, out[out.length - 1]) : v);
    return out;
  }

  function nearestIndex(times, t) {
    let best = 0;
    times.forEach((x, i) => Math.abs(x - t) < Math.abs(times[best] - t) && (best = i));
    return best;
  }

  function drawCurves() {
    const canvas = $("curves");
    const dpr = sizeCanvas(canvas);
    const ctx = canvas.getContext("2d");
    const W = canvas.width, H = canvas.height;
    ctx.fillStyle = "#101216";
    ctx.fillRect(0, 0, W, H);
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
    const playhead = X(requestTimeOf(state.clipTime));
    stroke(ctx, "#ff8c1a", dpr, () => (ctx.moveTo(playhead, top), ctx.lineTo(playhead, bottom)));
  }

  // ---- upload ----

  async function upload(fileList) {
    const files = [...fileList];
    const main = files.find((f) => /\.(json|gltf|glb|bvh)$/i.test(f.name));
    if (!main) return setStatus("choose a .json, .gltf, .glb or .bvh file", true);
    const ext = main.name.split(".").pop().toLowerCase();
    if (ext === "json") {
      state.pendingUpload = { url: "/v1/clips", body: await main.text(), type: "application/json" };
    } else {
      // Multipart even for one file: its file name names the clips it does not name itself.
      const form = new FormData();
      form.append("file", main, main.name);
      for (const f of files) if (f !== main) form.append("buffer", f, f.name);
      state.pendingUpload = { url: `/v1/clips/import?format=${ext}`, body: form };
    }
    await sendUpload();
  }

  async function sendUpload() {
    const req = state.pendingUpload;
    if (!req) return;
    setStatus("uploading…");
    const headers = authHeaders();
    if (req.type) headers["Content-Type"] = req.type;
    // The server refuses a write before reading its body, which a browser
    // sees as a failed upload rather than a 401; so ask first with an empty
    // body (401 without the token, else a 400 that stores nothing).
    const probe = await request("/v1/clips", {
      method: "POST",
      headers: { ...authHeaders(), "Content-Type": "application/json" },
      body: "",
    });
    const response = probe.status === 401 ? probe : await request(req.url, { method: "POST", headers, body: req.body });
    if (response.status === 401 || response.status === 403) {
      wantToken();
      const given = sessionStorage.getItem(TOKEN_KEY);
      const why = given ? `the token was refused (${await problemText(response)})` : "uploading needs the write token";
      return setStatus(`${why}: enter it under Token`, true);
    }
    state.pendingUpload = null;
    $("token-form").classList.remove("wanted");
    if (!response.ok) return setStatus(`upload refused: ${await problemText(response)}`, true);
    const body = await response.json();
    const created = body.clips || [body];
    await loadClips();
    setStatus(`uploaded ${created.map((c) => c.name).join(", ")}`);
    if (created.length) await selectClip(created[0].id);
  }

  function setupUpload() {
    const drop = $("drop");
    const report = (e) => setStatus(e.message, true);
    $("file").addEventListener("change", (e) => upload(e.target.files).catch(report));
    for (const type of ["dragenter", "dragover"])
      document.addEventListener(type, (e) => {
        e.preventDefault();
        drop.classList.add("over");
      });
    document.addEventListener("dragleave", () => drop.classList.remove("over"));
    document.addEventListener("drop", (e) => {
      e.preventDefault();
      drop.classList.remove("over");
      upload(e.dataTransfer.files).catch(report);
    });
    $("token-form").addEventListener("submit", (e) => {
      e.preventDefault();
      const token = $("token").value.trim();
      if (token) sessionStorage.setItem(TOKEN_KEY, token);
      else sessionStorage.removeItem(TOKEN_KEY);
      $("token-form").classList.remove("wanted");
      setStatus(token ? "token saved for this tab" : "no token");
      // Retry what the token was for: a pending upload, and the list.
      loadClipsOrExplain().then(() => sendUpload()).catch(report);
    });
    $("token-forget").addEventListener("click", () => {
      sessionStorage.removeItem(TOKEN_KEY);
      $("token").value = "";
      setStatus("token forgotten");
    });
    if (sessionStorage.getItem(TOKEN_KEY)) $("token").value = sessionStorage.getItem(TOKEN_KEY);
  }

  // ---- wiring ----

  function setup() {
    const report = (e) => setStatus(e.message, true);
    $("filter").addEventListener("input", renderClips);
    $("play").addEventListener("click", togglePlay);
    const seek = $("seek");
    seek.addEventListener("pointerdown", () => (viewer.seeking = true));
    seek.addEventListener("change", () => (viewer.seeking = false));
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
      // kept only if it is one the server takes (SPEC §5: within ±1000).
      if (Math.abs(speed) <= 1000) state.speed = speed;
      send({ op: "speed", speed });
    });
    document.addEventListener("keydown", onKey);
    for (const id of ["fps", "playback", "space", "ease"]) $(id).addEventListener("change", restartStream);
    $("curve-joint").addEventListener("change", () => {
      setupChannels();
      loadCurve().catch(report);
    });
    $("curve-channel").addEventListener("change", () => {
      showRotationChoice();
      loadCurve().catch(report);
    });
    $("curve-rotation").addEventListener("change", () => loadCurve().catch(report));
    setupOrbit();
    setupUpload();
    window.addEventListener("resize", () => (requestDraw(), drawCurves()));
    requestDraw();
    drawCurves();
    return loadClipsOrExplain();
  }

  /// The scene's camera now, in the scene canvas's pixels.
  function sceneCamera() {
    const canvas = $("scene");
    return { ...cameraBasis(canvas, canvas.width, canvas.height), dpr: window.devicePixelRatio || 1 };
  }

  Object.assign(viewer, {
    selectClip, adoptClip, loadClips, api, postJson, setStatus, describeProblem, problemText, authHeaders, streamProtocols,
    send, refusedControl, openStream, stopStream, setPlaying, showPoseAt, requestDraw, sceneCamera, toCamera, toScreen, options,
  });
  viewer.ready = setup();
})();
