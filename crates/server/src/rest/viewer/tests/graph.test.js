// Unit tests of the graph panel's pure parts (../graph.js): the controls a
// graph document gets, and its report as text: `node --test`.
import { test } from "node:test";
import assert from "node:assert/strict";

import { heldSettings } from "../composition.js";
import { describeState, describeWeights, parameterControls } from "../graph.js";

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
