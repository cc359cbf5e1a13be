// The clip library: one row per clip with what tells clips apart (a short
// id, version, when it was last changed, joints, duration, tags, a
// thumbnail), a filter by name or tag, clips sharing a name marked, and
// rename, replace and delete on the row (write scope; a refusal points at
// the token field).

import { api } from "./api.js";
import { forgetClip, loadClips, selectClip } from "./clips.js";
import { $, el, setStatus } from "./dom.js";
import { on } from "./events.js";
import { state } from "./state.js";
import { formatSeconds } from "./status.js";
import { thumbnail } from "./thumbs.js";
import { importWarnings, uploadFiles } from "./upload.js";

const report = (e) => setStatus(e.message, true);

/// The id as the row shows it: its last 8 characters (a UUIDv7 starts with
/// its creation time, so ids made together share their first ones).
export const shortId = (id) => (id.length > 8 ? `…${id.slice(-8)}` : id);

/// When a clip last changed, as a person reads it: the time today, else the date.
function when(iso) {
  const d = new Date(iso);
  if (Number.isNaN(d.getTime())) return iso;
  const today = new Date().toDateString() === d.toDateString();
  return today ? d.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit" }) : d.toISOString().slice(0, 10);
}

/// Whether a clip passes the filter: its name or one of its tags contains
/// the text (any case); `tag:x` asks for the tag x exactly.
export function matches(clip, filter) {
  const needle = filter.trim().toLowerCase();
  if (!needle) return true;
  const tags = (clip.tags || []).map((t) => t.toLowerCase());
  if (needle.startsWith("tag:")) return tags.includes(needle.slice(4).trim());
  return clip.name.toLowerCase().includes(needle) || tags.some((t) => t.includes(needle));
}

/// How many clips carry each name (more than one: the rows are marked).
export function nameCounts(clips) {
  const counts = new Map();
  for (const c of clips) counts.set(c.name, (counts.get(c.name) || 0) + 1);
  return counts;
}

/// A rename or delete confirmation open on a row: the list shown again (a
/// refresh, a token entered) keeps it open. `{ id, kind, value? }` or null.
let editing = null;

function render() {
  const filter = $("filter").value;
  const counts = nameCounts(state.clips);
  const rows = state.clips.filter((c) => matches(c, filter)).map((c) => row(c, counts.get(c.name)));
  $("clips").replaceChildren(...rows);
  const open = editing && rows.find((li) => li.dataset.id === editing.id);
  const clip = open && state.clips.find((c) => c.id === editing.id);
  if (!clip) editing = null;
  else if (editing.kind === "rename") startRename(open, clip, editing.value);
  else confirmDelete(open, clip);
}

/// Closes what was open on a row, and shows the list as it is.
function closeEditing() {
  editing = null;
  render();
}

function row(clip, sameName) {
  const name = el("span", { className: "name", textContent: clip.name });
  const head = el("div", { className: "head" }, name);
  if (sameName > 1) head.append(el("span", { className: "dup", textContent: `×${sameName}`, title: `${sameName} clips are named ${clip.name}` }));
  const facts = `${shortId(clip.id)} · v${clip.version} · ${when(clip.updated_at)}`;
  const details = el("small", { className: "facts", textContent: facts, title: `id ${clip.id}, updated ${clip.updated_at}` });
  const tagText = (clip.tags || []).map((t) => `#${t}`).join(" ");
  const shape = el("small", { className: "shape", textContent: `${clip.joints} joints · ${formatSeconds(clip.duration)} s` });
  const tags = el("small", { className: "tags", textContent: tagText, title: tagText });
  const actions = el(
    "div",
    { className: "actions" },
    button("Rename", `Rename ${clip.name}`, () => startRename(li, clip)),
    button("Replace", `Upload a file as ${clip.name}'s next version`, () => chooseReplacement(clip)),
    button("Delete", `Delete ${clip.name}`, () => confirmDelete(li, clip)),
  );
  const thumb = el("canvas", { className: "thumb", width: 48, height: 48, ariaHidden: "true" });
  const text = el("div", { className: "text" }, head, details, shape, tags, actions);
  const li = el("li", {}, thumb, text);
  li.dataset.id = clip.id;
  li.classList.toggle("selected", state.clip?.id === clip.id);
  li.classList.toggle("duplicate", sameName > 1);
  li.addEventListener("click", (e) => {
    if (e.target instanceof HTMLElement && e.target.closest(".actions, input")) return;
    selectClip(clip.id).catch(report);
  });
  thumbnail(clip, thumb).catch(() => thumb.classList.add("failed"));
  return li;
}

function button(label, title, action) {
  return el("button", { type: "button", textContent: label, title, onclick: (e) => (e.stopPropagation(), action()) });
}

/// A write the server refused for want of a token or scope points at the token field.
async function write(path, options, what) {
  try {
    return await api(path, options);
  } catch (e) {
    setStatus(`${what}: ${e.message}${/\b40[13]\b/.test(e.message) ? " — enter the write token under Token" : ""}`, true);
    throw e;
  }
}

// ---- rename: the name becomes a field; Enter sends a merge patch, Escape puts it back ----

function startRename(li, clip, value = clip.name) {
  editing = { id: clip.id, kind: "rename", value };
  const field = el("input", { type: "text", value, className: "rename", ariaLabel: `New name for ${clip.name}` });
  li.querySelector(".name").replaceWith(field);
  field.focus();
  field.select();
  field.addEventListener("input", () => (editing.value = field.value));
  field.addEventListener("keydown", (e) => {
    e.stopPropagation(); // the page's keys are not this field's
    if (e.key === "Escape") closeEditing();
    if (e.key === "Enter") rename(clip, field.value.trim()).catch(() => {});
  });
}

async function rename(clip, name) {
  if (!name || name === clip.name) return closeEditing();
  await write(
    `/v1/clips/${encodeURIComponent(clip.id)}`,
    { method: "PATCH", headers: { "Content-Type": "application/merge-patch+json", "If-Match": clip.etag }, body: JSON.stringify({ name }) },
    `renaming ${clip.name}`,
  );
  editing = null;
  await refresh();
  setStatus(`renamed ${clip.name} to ${name}`);
}

// ---- replace: a file uploaded as the clip's next version ----

function chooseReplacement(clip) {
  const input = $("replace-file");
  input.onchange = () => {
    const files = [...input.files];
    input.value = "";
    if (files.length) uploadFiles(files, clip).catch(report);
  };
  input.click();
}

// ---- delete, after a confirmation on the row ----

function confirmDelete(li, clip) {
  editing = { id: clip.id, kind: "delete" };
  const ask = el(
    "div",
    { className: "confirm", role: "alertdialog", ariaLabel: `Delete ${clip.name}?` },
    `Delete ${clip.name} (v${clip.version})? `,
    button("Delete", `Delete ${clip.name} for good`, () => remove(clip).catch(() => {})),
    button("Keep", "Keep it", closeEditing),
  );
  ask.querySelector("button").classList.add("danger");
  li.querySelector(".actions").replaceWith(ask);
}

async function remove(clip) {
  await write(`/v1/clips/${encodeURIComponent(clip.id)}`, { method: "DELETE", headers: { "If-Match": clip.etag } }, `deleting ${clip.name}`);
  const wasShown = state.clip?.id === clip.id;
  editing = null;
  await refresh();
  // The clip shown is gone: show the first one left (or none).
  if (wasShown && state.clips.length) await selectClip(state.clips[0].id);
  else if (wasShown) forgetClip();
  setStatus(`deleted ${clip.name}`);
}

/// The list again from the server.
const refresh = () => loadClips();

/// The up-axis hint: the clip's import said it lies along Z (`looks_z_up`, docs/import.md).
function showUpHint(clip) {
  $("up-hint").hidden = !importWarnings(clip).includes("looks_z_up");
}

export function setup() {
  on("listChanged", render);
  on("clipSelected", showUpHint);
  on("clipAdopted", showUpHint);
  $("filter").addEventListener("input", render);
}
