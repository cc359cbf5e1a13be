// Joint names against the names an engine gave the same nodes. A stream names
// joints as the clip's source file did (`mixamorig:Hips`); engines rewrite
// some characters when they import that file: three.js's loaders keep a node
// name only after `PropertyBinding.sanitizeNodeName` (whitespace to `_`,
// `[ ] . : /` removed: `mixamorigHips`), Godot's importer turns `:` and `/`
// into `_` (`mixamorig_Hips`). A joint binds to the node of its exact name,
// else to the node of its rewritten name.

const THREE_RESERVED = /[[\].:/]/g;

/** three.js's `PropertyBinding.sanitizeNodeName`, which its GLTFLoader applies to every node name. */
export function threeName(name) {
  return name.replace(/\s/g, "_").replace(THREE_RESERVED, "");
}

/** The name Godot's scene importer gives a bone (`:` and `/` are not allowed in bone names). */
export function godotName(name) {
  return name.replace(/[:/]/g, "_");
}

/**
 * For each of `joints` (the stream's names), the index in `nodes` (the
 * engine's names) it binds to, or -1; `rewrite` is the engine's rule
 * (`threeName` by default). The first node of a repeated name wins.
 */
export function matchNames(joints, nodes, rewrite = threeName) {
  const index = new Map();
  nodes.forEach((name, i) => {
    if (!index.has(name)) index.set(name, i);
  });
  return joints.map((name) => index.get(name) ?? index.get(rewrite(name)) ?? -1);
}
