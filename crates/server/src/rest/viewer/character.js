// The character the page's motion plays on (docs/characters.md): picked in
// the composition panel, it makes the server retarget every layer onto the
// character's skeleton, so the poses, the skeleton drawn and the mesh are
// the character's, whatever rig the clips were made on.

import { api, listAll } from "./api.js";
import { $, el, row, setStatus } from "./dom.js";
import { emit } from "./events.js";
import { state } from "./state.js";

/// Every character's summary, page by page (as the clip list).
async function loadCharacters() {
  state.characters = await listAll("/v1/characters", "characters");
}

/// The picker's options: the clip's own skeleton, then every character.
function fill() {
  const select = $("character");
  const own = new Option("its own skeleton", "");
  const options = state.characters.map((c) => new Option(`${c.name}${c.mesh ? "" : " (no mesh)"}`, c.id));
  select.replaceChildren(own, ...options);
  select.value = state.character?.id ?? "";
}

/// Lists the characters again; `quiet`: a refusal says nothing (at startup,
/// the clip list already says what a missing or refused token means).
const refresh = (quiet = false) =>
  loadCharacters()
    .then(fill)
    .catch((e) => quiet || setStatus(`listing characters: ${e.message}`, true));

/// Plays the page's motion on character `id` (empty: on the clip's own
/// skeleton). The pose's joints change, so the page forgets the old ones.
/// `adopted`: a watched broadcast plays on it already (nothing to send).
export async function choose(id, adopted = false) {
  const doc = id ? await api(`/v1/characters/${encodeURIComponent(id)}`) : null;
  const summary = state.characters.find((c) => c.id === id);
  state.character = doc ? { id, name: summary?.name ?? doc.name ?? id, doc } : null;
  state.names = [];
  $("character").value = state.character?.id ?? "";
  emit("characterChanged", state.character, adopted);
}

export function setup() {
  const select = el("select", { id: "character", ariaLabel: "Character to play on" });
  $("composition").append(row(el("label", {}, "on ", select)));
  select.addEventListener("focus", () => refresh());
  select.addEventListener("change", () => choose(select.value).catch((e) => setStatus(`character: ${e.message}`, true)));
  fill();
  return refresh(true);
}
