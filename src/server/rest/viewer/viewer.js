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
  const COLORS = ["#ff5c5c", "#5cd65c", "#5c9dff", "#c8c8c8"]; // x, y, z, w

  const state = {
    clips: [],
    clip: null, // the selected clip's summary
    doc: null, // its document (skeleton, tracks)
    names: [], // joint names in pose order
    parents: [], // parent index per joint, -1 for roots
    positions: [], // model-space joint positions to draw
    ws: null,
    playing: false,
    requestTime: 0, // request time of the pose shown
    clipTime: 0, // its clip time (after playback and ease)
    frames: 0,
    seq: null,
    dropped: 0,
    latencyMs: null,
    camera: { yaw: 0.7, pitch: 0.35, dist: 5, target: [0, 1, 0], radius: 1 },
    curve: null, // the plotted series (read by the browser test)
    pendingUpload: null,
  };
  const viewer = { state, cspViolations: [] };
  window.inbetweenViewer = viewer;
  document.addEventListener("securitypolicyviolation", (e) =>
    viewer.cspViolations.push(`${e.violatedDirective} ${e.blockedURI}`),
  );

  // ---- REST helpers ----

  function authHeaders() {
    const token = sessionStorage.getItem(TOKEN_KEY);
    return token ? { Authorization: `Bearer ${token}` } : {};
  }

  async function problemText(response) {
    try {
      const p = await response.json();
      return `${p.code || response.status}: ${p.detail || p.title}`;
    } catch {
      return `HTTP ${response.status}`;
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
    if (!response.ok) throw new Error(await problemText(response));
    return response.json();
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
    renderClips();
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
    const summary = state.clips.find((c) => c.id === id);
    const doc = await api(`/v1/clips/${encodeURIComponent(id)}`);
    Object.assign(state, { clip: summary, doc, names: [], frames: 0, seq: null, dropped: 0, latencyMs: null });
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

  // ---- poses and the skeleton ----

  function parentsOf(names) {
    const joints = state.doc?.skeleton?.joints || [];
    const parentName = new Map(joints.map((j) => [j.name, j.parent]));
    const index = new Map(names.map((n, i) => [n, i]));
    return names.map((n) => (parentName.get(n) == null ? -1 : index.get(parentName.get(n)) ?? -1));
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
    }
    state.positions = modelPositions(pose);
    state.requestTime = pose.time;
    state.clipTime = pose.clip_time;
    requestDraw();
  }

  function options() {
    const o = { space: $("space").value, ease: $("ease").value };
    if ($("playback").value) o.playback = $("playback").value;
    return o;
  }

  async function showPoseAt(t) {
    const q = new URLSearchParams({ t: String(t), ...options() });
    applyPose(await api(`/v1/clips/${encodeURIComponent(state.clip.id)}/pose?${q}`));
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

  function openStream() {
    const ws = new WebSocket(streamUrl());
    state.ws = ws;
    // The readout counts this stream's ticks: each frame's `dropped` is the
    // ticks skipped since the previous frame, so the total is their sum.
    Object.assign(state, { frames: 0, seq: null, dropped: 0 });
    ws.onmessage = (message) => {
      if (typeof message.data !== "string") return;
      const frame = JSON.parse(message.data);
      if (frame.error) return setStatus(frame.error, true);
      const nowNanos = (performance.timeOrigin + performance.now()) * 1e6;
      state.frames += 1;
      state.seq = frame.seq;
      state.dropped += frame.dropped;
      state.latencyMs = (nowNanos - frame.sent_at_unix_nanos) / 1e6;
      if (frame.events?.length) setStatus(`event: ${frame.events.map((e) => e.name).join(", ")}`);
      applyPose(frame.pose);
      updateReadout();
    };
    ws.onclose = (e) => {
      if (state.ws !== ws) return;
      state.ws = null;
      setPlaying(false);
      if (e.code !== 1000 && e.code !== 1005) setStatus(`stream closed (${e.code}) ${e.reason}`, true);
    };
  }

  function send(control) {
    if (state.ws?.readyState === WebSocket.OPEN) state.ws.send(JSON.stringify(control));
  }

  function stopStream() {
    const ws = state.ws;
    state.ws = null;
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
    openStream();
    setPlaying(true);
  }

  function setPlaying(playing) {
    state.playing = playing;
    $("play").textContent = playing ? "Pause" : "Play";
  }

  function togglePlay() {
    if (!state.clip) return;
    if (!state.ws) {
      openStream();
      setPlaying(true);
    } else {
      send({ op: state.playing ? "pause" : "play" });
      setPlaying(!state.playing);
    }
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

  function sizeCanvas(canvas, aspect) {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
    const h = Math.round(w * aspect);
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

  function drawScene() {
    const canvas = $("scene");
    const dpr = sizeCanvas(canvas, 0.6);
    const ctx = canvas.getContext("2d");
    ctx.fillStyle = "#101216";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    const cam = cameraBasis(canvas, canvas.width, canvas.height);
    const { target, radius } = state.camera;
    const step = 10 ** Math.floor(Math.log10(radius)) / 2;
    const n = Math.ceil((2 * radius) / step);
    const ox = Math.round(target[0] / step) * step, oz = Math.round(target[2] / step) * step;
    stroke(ctx, "#2a2f3a", dpr, () => {
      for (let i = -n; i <= n; i++) {
        line(ctx, cam, [ox + i * step, 0, oz - n * step], [ox + i * step, 0, oz + n * step]);
        line(ctx, cam, [ox - n * step, 0, oz + i * step], [ox + n * step, 0, oz + i * step]);
      }
    });
    const axis = 2 * step;
    [[axis, 0, 0], [0, axis, 0], [0, 0, axis]].forEach((end, i) =>
      stroke(ctx, COLORS[i], 2 * dpr, () => line(ctx, cam, [0, 0, 0], end)),
    );
    const pos = state.positions;
    stroke(ctx, "#c8d0dc", 2.5 * dpr, () => {
      state.parents.forEach((p, i) => {
        if (p >= 0 && pos[p] && pos[i]) line(ctx, cam, pos[p], pos[i]);
      });
    });
    ctx.fillStyle = "#ff8c1a";
    for (const p of pos) {
      const v = toCamera(cam, p);
      if (v[2] < cam.near) continue;
      const [x, y] = toScreen(cam, v);
      ctx.beginPath();
      ctx.arc(x, y, 4 * dpr, 0, 2 * Math.PI);
      ctx.fill();
    }
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

  function setupCurveSelectors() {
    const joints = [];
    for (const t of state.doc.tracks) if (!joints.includes(t.joint)) joints.push(t.joint);
    const select = $("curve-joint");
    select.replaceChildren(...joints.map((j) => new Option(j, j)));
    setupChannels();
  }

  function setupChannels() {
    const joint = $("curve-joint").value;
    const channels = state.doc.tracks.filter((t) => t.joint === joint).map((t) => t.channel);
    $("curve-channel").replaceChildren(...channels.map((c) => new Option(c, c)));
  }

  async function loadCurve() {
    const joint = $("curve-joint").value, channel = $("curve-channel").value;
    if (!state.clip || !joint || !channel) {
      state.curve = null;
      return drawCurves();
    }
    const { id, start, end } = state.clip;
    const track = state.doc.tracks.find((t) => t.joint === joint && t.channel === channel);
    const fps = end > start ? Math.min(240, Math.max(1, CURVE_POINTS / (end - start))) : 1;
    const request = { start, end, fps, space: "local", playback: "once", ease: $("ease").value };
    const { poses } = await postJson(`/v1/clips/${encodeURIComponent(id)}/sample`, request);
    const times = poses.map((p) => p.time);
    const values = poses.map((p) => p.joints.find((j) => j.name === joint)[channel]);
    const keys = track.times.map((t, i) => ({ time: requestTimeOf(t), clipTime: t, value: track.values[i] }));
    state.curve = { clip: id, joint, channel, request, times, values, keys };
    const ends = track.ends ? `, ends ${track.ends}` : "";
    $("curve-info").textContent = `${track.interpolation}${ends} · ${track.times.length} keys · ${request.ease}`;
    viewer.curve = state.curve;
    drawCurves();
  }

  function drawCurves() {
    const canvas = $("curves");
    const dpr = sizeCanvas(canvas, 0.25);
    const ctx = canvas.getContext("2d");
    const W = canvas.width, H = canvas.height;
    ctx.fillStyle = "#101216";
    ctx.fillRect(0, 0, W, H);
    const curve = state.curve;
    if (!curve || !curve.times.length) return;
    let lo = Infinity, hi = -Infinity;
    for (const v of [...curve.values, ...curve.keys.map((k) => k.value)])
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
    ctx.fillText(hi.toPrecision(4), 4 * dpr, top + 8 * dpr);
    ctx.fillText(lo.toPrecision(4), 4 * dpr, bottom);
    ctx.fillText(`${t0.toFixed(2)} s`, left, H - 5 * dpr);
    ctx.fillText(`${t1.toFixed(2)} s`, right - 40 * dpr, H - 5 * dpr);
    if (lo < 0 && hi > 0) stroke(ctx, "#353a45", dpr, () => (ctx.moveTo(left, Y(0)), ctx.lineTo(right, Y(0))));
    const components = curve.values[0].length;
    for (let c = 0; c < components; c++) {
      stroke(ctx, COLORS[c], 1.5 * dpr, () =>
        curve.times.forEach((t, i) => (i ? ctx.lineTo(X(t), Y(curve.values[i][c])) : ctx.moveTo(X(t), Y(curve.values[i][c])))),
      );
      ctx.fillStyle = COLORS[c];
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
    } else if (files.length > 1) {
      const form = new FormData();
      form.append("file", main, main.name);
      for (const f of files) if (f !== main) form.append("buffer", f, f.name);
      state.pendingUpload = { url: `/v1/clips/import?format=${ext}`, body: form };
    } else {
      state.pendingUpload = { url: `/v1/clips/import?format=${ext}`, body: main, type: "application/octet-stream" };
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
    if (response.status === 401) {
      $("token-form").hidden = false;
      $("token").focus();
      const given = sessionStorage.getItem(TOKEN_KEY);
      return setStatus(given ? "the write token was refused" : "uploading needs the write token", true);
    }
    state.pendingUpload = null;
    $("token-form").hidden = true;
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
      sessionStorage.setItem(TOKEN_KEY, $("token").value.trim());
      sendUpload().catch(report);
    });
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
    $("speed").addEventListener("change", () => send({ op: "speed", speed: Number($("speed").value) || 1 }));
    for (const id of ["fps", "playback", "space", "ease"]) $(id).addEventListener("change", restartStream);
    $("curve-joint").addEventListener("change", () => {
      setupChannels();
      loadCurve().catch(report);
    });
    $("curve-channel").addEventListener("change", () => loadCurve().catch(report));
    setupOrbit();
    setupUpload();
    window.addEventListener("resize", () => (requestDraw(), drawCurves()));
    requestDraw();
    drawCurves();
    loadClips().catch(report);
  }

  viewer.selectClip = selectClip;
  viewer.loadClips = loadClips;
  setup();
})();
