// Unit tests of the graph panel's pure parts (../graph.js): the controls a
// graph document gets, its report as text, the clip of its output skeleton,
// and the motion the page plays over it (../composition.js): `node --test`.
import { test } from "node:test";
import assert from "node:assert/strict";

import { heldSettings, motion, panel } from "../composition.js";
import { clipIdOf, describeState, describeWeights, outputClip, parameterControls } from "../graph.js";
import { state } from "../state.js";

const doc = {
  parameters: {
    speed: { type: "float", default: 0, min: 0, max: 6 },
    lean: { type: "float", default: 9, min: -1, max: 1 },
    survey: { type: "bool", default: true },
    jump: { type: "trigger" },
  },
  nodes: {
    walkrun: { blend1d: { parameter: "speed", points: [{ clip: "id-s", at: 0 }, { clip: "name:Walk", at: 1.5 }, { clip: "id-r", at: 5 }] } },
  },
};

test("each parameter gets a control in the document's order, a float's default clamped into its range", () => {
  assert.deepEqual(parameterControls(doc), [
    { name: "speed", kind: "float", min: 0, max: 6, value: 0 },
    { name: "lean", kind: "float", min: -1, max: 1, value: 1 },
    { name: "survey", kind: "bool", value: true },
    { name: "jump", kind: "trigger" },
  ]);
  assert.deepEqual(parameterControls({}), []);
});

test("the settings that hold leave triggers out (a trigger lasts one tick)", () => {
  assert.deepEqual(heldSettings(parameterControls(doc)), { speed: 0, lean: 1, survey: true });
});

test("the state, or the transition in progress with its alpha", () => {
  assert.equal(describeState({ state: "walk", weights: {} }), "walk");
  assert.equal(describeState({ state: "run", transition: { from: "walk", to: "run", alpha: 0.4166 } }), "walk → run (α 0.42)");
  assert.equal(describeState(null), "");
});

test("a blend's weights by clip name, heaviest first, zeros left out", () => {
  const names = { "id-s": "Survey", "id-r": "Run" };
  assert.deepEqual(describeWeights(doc, "walkrun", [0, 0.25, 0.75], names), [
    { name: "Run", weight: 0.75 },
    { name: "Walk", weight: 0.25 },
  ]);
  assert.deepEqual(describeWeights(doc, "gone", [1]), [{ name: "point 0", weight: 1 }]);
});

test("the output skeleton's clip: the initial state's node's first clip, through blends and stacks", () => {
  const nodes = {
    idle: { clip: "name:Survey" },
    move: { blend1d: { parameter: "speed", points: [{ clip: "id-w", at: 1 }, { clip: "id-r", at: 3 }] } },
    aim: { layers: [{ node: "move" }, { clip: "id-a", mask: { joints: { spine: 1 } } }] },
  };
  const machine = (initial) => ({ nodes, machine: { initial, states: { idle: { node: "idle" }, moving: { node: "move" }, aiming: { node: "aim" } } } });
  assert.equal(outputClip(machine("idle")), "name:Survey");
  assert.equal(outputClip(machine("moving")), "id-w");
  assert.equal(outputClip(machine("aiming")), "id-w");
  assert.equal(outputClip({ nodes, output: "aim" }), "id-w");
  assert.equal(outputClip({ nodes: { a: { layers: [{ node: "b" }] }, b: { layers: [{ node: "a" }] } }, output: "a" }), null);
  assert.equal(outputClip({ nodes, output: "gone" }), null);
});

test("a clip reference's id: by name from the list, else the id itself", () => {
  const clips = [{ id: "id-s", name: "Survey" }];
  assert.equal(clipIdOf("name:Survey", clips), "id-s");
  assert.equal(clipIdOf("name:Gone", clips), null);
  assert.equal(clipIdOf("id-x", clips), "id-x");
  assert.equal(clipIdOf(null, clips), null);
});

test("a graph's motion carries the page's character, root motion with its joint, IK and springs", () => {
  const page = { graph: state.graph, character: state.character };
  const before = { ...panel, springs: { ...panel.springs } };
  try {
    state.graph = { id: "g1", name: "fox", doc: {}, controls: [] };
    Object.assign(panel, {
      layers: [{ clip: "id-s", weight: 0.5, mask: "spine" }], // a clip's layers: not the graph's
      rootMode: "report",
      rootJoint: "b_Hip_01",
      ik: { kind: "two_bone", joint: "foot", joints: ["thigh", "shin", "foot"], target: [0.1, 0, 0.3] },
    });
    assert.deepEqual(motion(), {
      layers: [{ graph: "g1" }],
      root_motion: { mode: "report", joint: "b_Hip_01" },
      ik: [{ kind: "two_bone", joints: ["thigh", "shin", "foot"], target: [0.1, 0, 0.3] }],
    });

    state.character = { id: "c1", name: "cesium", doc: {} };
    Object.assign(panel, { rootMode: "extract", rootJoint: null, ik: { kind: "aim", joint: "head", target: [0, 2, 1] } });
    panel.springs = { chains: [{ name: "tail", joints: ["t1", "t2"] }], on: true, stiffness: 2, drag: 0.5, gravity: 10 };
    assert.deepEqual(motion(), {
      layers: [{ graph: "g1" }],
      root_motion: { mode: "extract" },
      ik: [{ kind: "aim", joint: "head", target: [0, 2, 1] }],
      character: "c1",
      springs: [{ name: "tail", joints: ["t1", "t2"], stiffness: 2, drag: 0.5, gravity: [0, -10, 0] }],
    });
    assert.equal(motion({ ik: false }).ik, undefined);

    Object.assign(panel, { rootMode: "", ik: null });
    panel.springs.on = false;
    state.character = null;
    assert.deepEqual(motion(), { layers: [{ graph: "g1" }] });
  } finally {
    Object.assign(state, page);
    Object.assign(panel, before);
  }
});
