// Uploading clips (a dropped or chosen .json, .gltf, .glb or .bvh, with a
// glTF's buffers), and the token form: the token is kept in this tab, and
// entering one retries what wanted it (a pending upload, the list).

import { authHeaders, problemText, request, saveToken, savedToken, wantToken } from "./api.js";
import { loadClips, loadClipsOrExplain, selectClip } from "./clips.js";
import { $, setStatus } from "./dom.js";
import { state } from "./state.js";

async function upload(fileList) {
  const files = [...fileList];
  const main = files.find((f) => /\.(json|gltf|glb|bvh)$/i.test(f.name));
  if (!main) return setStatus("choose a .json, .gltf, .glb or .bvh file", true);
  const ext = main.name.split(".").pop().toLowerCase();
  if (ext === "json") {
    // Dropping a file again makes a new version of the clip it made (names identify clips).
    state.pendingUpload = { url: "/v1/clips?replace=true", body: await main.text(), type: "application/json" };
  } else {
    // Multipart even for one file: its file name names the clips it does not name itself.
    const form = new FormData();
    form.append("file", main, main.name);
    for (const f of files) if (f !== main) form.append("buffer", f, f.name);
    state.pendingUpload = { url: `/v1/clips/import?format=${ext}&replace=true`, body: form };
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
    const given = savedToken();
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

export function setup() {
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
    saveToken(token);
    $("token-form").classList.remove("wanted");
    setStatus(token ? "token saved for this tab" : "no token");
    // Retry what the token was for: a pending upload, and the list.
    loadClipsOrExplain().then(() => sendUpload()).catch(report);
  });
  $("token-forget").addEventListener("click", () => {
    saveToken(null);
    $("token").value = "";
    setStatus("token forgotten");
  });
  if (savedToken()) $("token").value = savedToken();
}
