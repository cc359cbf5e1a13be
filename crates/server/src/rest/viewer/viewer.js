// The inbetween viewer: lists clips, plays a clip's WebSocket stream as a
// 3D skeleton (or its skinned mesh) and plots one channel's sampled curve
// with its keys; composes clips into motions with IK handles, plays them on
// a character, and broadcasts them. It talks only to the REST API and the streams of the
// server that served it.
//
// This is the page's entry module: index.html loads it (and preloads the
// rest); it sets the parts up in order and loads the clip list. The parts
// are ES modules that import what they use from each other:
//
//   math.js         vectors, quaternions, transforms, matrices, Euler angles, eases, the camera (unit-tested: tests/)
//   dom.js          element lookup and creation, the status line, canvas helpers
//   events.js       the page's named events (frame, pose, overlay, clip selected, …)
//   state.js        the page's state, and the broadcast watched
//   api.js          REST calls, the token, problem documents, stream subprotocols
//   settings.js     the playback settings the controls hold; clip time back to request time
//   pose.js         a pose into the page's state (parents, drawn joints, model positions)
//   scene.js        the 3D view: camera, ground, skeleton solids, orbit
//   mesh.js         the skinned mesh in WebGL2, under the skeleton
//   curves.js       the curve plot
//   player.js       the stream, play/pause/seek/speed/keys, the readout
//   controls.js     where live controls go (socket or broadcast route), refusals, scope
//   status.js       what the header and status line say: a reducer of the page's happenings (unit-tested)
//   render.js       the one animation-frame loop: updates, then draws, some throttled
//   clips.js        the clip list, selecting and adopting a clip
//   library.js      the list's rows: facts, filter, duplicates, rename, replace, delete
//   thumbs.js       a pose thumbnail per clip version (memory and IndexedDB)
//   upload.js       uploads and the token form
//   composition.js  the motion played: layers, root motion, IK handle
//   panel.js        the composition and IK panel
//   character.js    the character the motion plays on (retargeted on the server)
//   graph.js        the graph played: a control per parameter, live `set`s, its report
//   springs.js      spring chains: the clip's and the page's, drawn; on/off, reset
//   broadcast.js    creating and watching broadcasts

import * as broadcast from "./broadcast.js";
import * as character from "./character.js";
import * as clips from "./clips.js";
import { panel as composition } from "./composition.js";
import * as curves from "./curves.js";
import * as graph from "./graph.js";
import * as library from "./library.js";
import { toCamera, toScreen } from "./math.js";
import * as mesh from "./mesh.js";
import * as panel from "./panel.js";
import * as player from "./player.js";
import * as scene from "./scene.js";
import * as springs from "./springs.js";
import * as thumbs from "./thumbs.js";
import { broadcast as watched, state } from "./state.js";
import * as upload from "./upload.js";

const cspViolations = [];
document.addEventListener("securitypolicyviolation", (e) => cspViolations.push(`${e.violatedDirective} ${e.blockedURI}`));

library.setup();
player.setup();
curves.setup();
scene.setup();
upload.setup();
window.addEventListener("resize", () => (scene.requestDraw(), curves.drawCurves()));
scene.requestDraw();
curves.drawCurves();
const ready = clips.loadClipsOrExplain();
// Listeners of one event run in setup order: the panel's, the broadcast's, then the mesh's.
panel.setup();
character.setup();
graph.setup();
springs.setup();
broadcast.setup(ready);
mesh.setup();

/// What the browser tests (tests/service/viewer) read of the page: its
/// state, the composition, the broadcast watched, the mesh, the plotted
/// curve, the skeleton drawn, CSP violations, and the scene's camera maths
/// to find a point on screen. Only the tests use it; no module reads it.
window.inbetweenViewer = Object.freeze({
  state,
  panel: composition,
  broadcast: watched,
  mesh: mesh.mesh,
  thumbnails: thumbs.stats,
  cspViolations,
  get curve() {
    return state.curve;
  },
  get drawn() {
    return scene.drawnSkeleton();
  },
  sceneCamera: scene.sceneCamera,
  toCamera,
  toScreen,
});
