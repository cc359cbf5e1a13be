// Uploading clips (a dropped or chosen .json, .gltf, .glb or .bvh, with a
// glTF's buffers), and the token form: the token is kept in this tab, and
// entering one retries what wanted it (a pending upload, the list).

import { authHeaders, problemText, request, saveToken, savedToken, wantToken } from "./api.js";
import { loadClips, loadClipsOrExplain, selectClip } from "./clips.js";
import { $, setStatus } from "./dom.js";
import { state } from "./state.js";

/// Uploads a dropped or chosen file (with a glTF's buffers). With
/// `replacing` (a clip of the library) it is sent under that clip's name, so
/// that it becomes its next version: a clip document's `name` is set to it,
/// an imported file is named after it (a glTF whose animations have names
/// keeps them, and makes those clips instead).
export async function uploadFiles(files, replacing = null) {
  const main = files.find((f) => /\.(json|gltf|glb|bvh)$/i.test(f.name));
  if (!main) return setStatus("choose a .json, .gltf, .glb or .bvh file", true);
  const ext = main.name.split(".").pop().toLowerCase();
  if (ext === "json") {
    // Dropping a file again makes a new version of the clip it made (names identify clips).
    let body = await main.text();
    if (replacing) body = JSON.stringify({ ...JSON.parse(body), name: replacing.name });
    state.pendingUpload = { url: "/v1/clips?replace=true", body, type: "application/json", replacing };
  } else {
    // Multipart even for one file: its file name names the clips it does not name itself.
    const form = new FormData();
    form.append("file", main, replacing ? `${replacing.name}.${ext}` : main.name);
    for (const f of files) if (f !== main) form.append("buffer", f, f.name);
    state.pendingUpload = { url: `/v1/clips/import?format=${ext}&replace=true`, body: form, replacing };
  }
  await sendUpload();
}

/// The import warnings the page saw, by clip id and version (the server
/// gives them only in the upload's answer): kept in this browser, for the
/// up-axis hint (`looks_z_up`, docs/import.md).
const WARNINGS_KEY = "inbetween.warnings";

export function importWarnings(clip) {
  try {
    return JSON.parse(localStorage.getItem(WARNINGS_KEY) || "{}")[`${clip.id}@${clip.version}`] || [];
  } catch {
    return [];
  }
}

function keepWarnings(clips, warnings) {
  const codes = [...new Set((warnings || []).map((w) => w.code))];
  try {
    const kept = JSON.parse(localStorage.getItem(WARNINGS_KEY) || "{}");
    for (const c of clips) kept[`${c.id}@${c.version}`] = codes;
    localStorage.setItem(WARNINGS_KEY, JSON.stringify(kept));
  } catch {
    // Storage full or refused: the hint is a convenience.
  }
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
  keepWarnings(created, body.warnings);
  await loadClips();
  const replaced = req.replacing && created.find((c) => c.id === req.replacing.id);
  if (created.length) await selectClip((replaced || created[0]).id);
  if (replaced) setStatus(`replaced ${replaced.name}: now version ${replaced.version}`);
  else if (req.replacing) setStatus(`the file names its clips itself: uploaded ${created.map((c) => c.name).join(", ")}, ${req.replacing.name} unchanged`, true);
  else setStatus(`uploaded ${created.map((c) => c.name).join(", ")}`);
}

export function setup() {
  const drop = $("drop");
  const report = (e) => setStatus(e.message, true);
  $("file").addEventListener("change", (e) => uploadFiles([...e.target.files]).catch(report));
  for (const type of ["dragenter", "dragover"])
    document.addEventListener(type, (e) => {
      e.preventDefault();
      drop.classList.add("over");
    });
  document.addEventListener("dragleave", () => drop.classList.remove("over"));
  document.addEventListener("drop", (e) => {
    e.preventDefault();
    drop.classList.remove("over");
    uploadFiles([...e.dataTransfer.files]).catch(report);
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
