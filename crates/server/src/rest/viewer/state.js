// The page's state: what is selected, shown and playing, and the broadcast
// watched. One object each, imported by the modules that read or change them.

import { initialStatus } from "./status.js";

export const state = {
  clips: [],
  clip: null, // the selected clip's summary
  doc: null, // its document (skeleton, tracks)
  names: [], // joint names in pose order
  parents: [], // parent index per joint, -1 for roots
  drawnJoints: [], // per joint: drawn (a joint, not a placement node)
  positions: [], // model-space joint positions to draw
  selectedJoint: null, // the joint picked in the view (scene.js), if any
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
  compactLayout: null, // the running stream's compact layout (docs/compact-frames.md), or null: JSON frames
  latencyMs: null, // sent → received, of the newest frame
  lateMs: null, // sent → shown (the animation frame that drew it): how far the page is behind
  pendingFrame: null, // the newest frame received, not shown yet (render.js shows it)
  status: initialStatus, // what the header and status line say (status.js; dom.js dispatchStatus)
  camera: { yaw: 0.7, pitch: 0.35, dist: 5, target: [0, 1, 0], radius: 1 },
  curve: null, // the plotted series (read by the browser test)
  pendingUpload: null,
  watching: null, // the id of the broadcast this page watches (broadcast.js), if any
  characters: [], // the server's characters' summaries (character.js)
  graphs: [], // the server's graphs' summaries (graph.js)
  graph: null, // { id, name, doc, controls } the page plays (docs/graphs.md), or null: the layers
  character: null, // { id, name, doc } the page's motion plays on (docs/characters.md), or null: the clip's own skeleton
};

/// The skeleton the poses shown are on: the character's, else the clip's.
export const shownSkeleton = () => (state.character ? state.character.doc.skeleton : state.doc?.skeleton);

/// The broadcast watched (broadcast.js; its controls in controls.js).
export const broadcast = {
  id: null, // the broadcast watched
  summary: null, // its GET summary when the page started watching it
  canControl: null, // whether this caller may control it (null: not known yet)
  link: null,
  frames: new Map(), // seq → pose of the frames received while watching
  selecting: false, // selecting the broadcast's clip (not leaving it)
  lastControl: null, // { op, seq } of the last control the server took
};
