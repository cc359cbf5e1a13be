// A pose from the server into the page's state: the joints' order, parents
// and which of them are drawn, and their model-space positions.

import { emit } from "./events.js";
import { modelTransforms } from "./math.js";
import { requestDraw } from "./scene.js";
import { shownSkeleton, state } from "./state.js";

function parentsOf(names) {
  const joints = shownSkeleton()?.joints || [];
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
/// joint to a drawn child. A character has no tracks: only its skin says
/// which nodes are joints.
function drawnJoints(names, parents) {
  const joints = new Map((shownSkeleton()?.joints || []).map((j) => [j.name, j]));
  const skinned = [...joints.values()].some((j) => j.inverse_bind);
  const animated = new Set(state.character ? names : (state.doc?.tracks || []).map((t) => t.joint));
  const children = names.map(() => 0);
  parents.forEach((p) => p >= 0 && (children[p] += 1));
  const placement = [];
  names.forEach((n, i) => {
    const p = parents[i];
    placement[i] = !animated.has(n) && children[i] <= 1 && (p < 0 || placement[p]);
  });
  return names.map((n, i) => !placement[i] && (!skinned || Boolean(joints.get(n)?.inverse_bind)));
}

/// Model-space positions from a pose: as sent for `space=model`, else
/// composed down the hierarchy here (docs/clip-format.md §2.8).
function modelPositions(pose) {
  if (pose.space === "model") return pose.joints.map((j) => j.translation);
  const locals = pose.joints.map((j) => ({ t: j.translation, q: j.rotation, s: j.scale }));
  return modelTransforms(locals, state.parents).map((m) => m.t);
}

/// Makes `pose` the one shown, tells the page (`pose`) and draws it.
export function applyPose(pose) {
  const names = pose.joints.map((j) => j.name);
  if (names.join("\n") !== state.names.join("\n")) {
    state.names = names;
    state.parents = parentsOf(names);
    state.drawnJoints = drawnJoints(names, state.parents);
  }
  state.positions = modelPositions(pose);
  state.requestTime = pose.time;
  state.clipTime = pose.clip_time;
  emit("pose", pose);
  requestDraw();
}
