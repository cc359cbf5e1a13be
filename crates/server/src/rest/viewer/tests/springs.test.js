// Unit tests of the springs panel's pure parts (../springs.js, and the
// motion's `springs` in ../composition.js): `node --test`.
import { test } from "node:test";
import assert from "node:assert/strict";

import { springsDoc, withSprings } from "../composition.js";
import { chainFrom, chainRoots } from "../springs.js";

// The Fox's tail and a leg, in skeleton order (a parent before its children).
const joints = [
  { name: "hips", parent: null },
  { name: "tail1", parent: "hips" },
  { name: "leg", parent: "hips" },
  { name: "b_ForeArm", parent: "hips" },
  { name: "b_LeftEar", parent: "hips" },
  { name: "ear_tip", parent: "b_LeftEar" },
  { name: "hand", parent: "b_ForeArm" },
  { name: "tail2", parent: "tail1" },
  { name: "foot", parent: "leg" },
  { name: "tail3", parent: "tail2" },
  { name: "toe_a", parent: "foot" },
  { name: "toe_b", parent: "foot" },
];

test("a chain runs from its root down the first child at each step to a leaf", () => {
  assert.deepEqual(chainFrom(joints, "tail1"), ["tail1", "tail2", "tail3"]);
  assert.deepEqual(chainFrom(joints, "leg"), ["leg", "foot", "toe_a"]);
  assert.deepEqual(chainFrom(joints, "tail3"), ["tail3"], "a leaf alone");
});

test("roots are joints with a child, in no chain yet, swingy names first", () => {
  assert.deepEqual(chainRoots(joints), ["tail1", "b_LeftEar", "tail2", "hips", "leg", "b_ForeArm", "foot"]);
  assert.deepEqual(chainRoots(joints, new Set(["tail1", "tail2"])), ["b_LeftEar", "hips", "leg", "b_ForeArm", "foot"]);
});

test("the page's chains become the motion's springs with one stiffness, drag and downward gravity", () => {
  const settings = { chains: [{ name: "tail1", joints: ["tail1", "tail2", "tail3"] }], on: true, stiffness: 0.8, drag: 0.3, gravity: 9.81 };
  assert.deepEqual(springsDoc(settings), [{ name: "tail1", joints: ["tail1", "tail2", "tail3"], stiffness: 0.8, drag: 0.3, gravity: [0, -9.81, 0] }]);
});

test("a graph's motion takes the chains when they are on, and none when off or empty", () => {
  const graph = { layers: [{ graph: "g1" }] };
  const chains = [{ name: "tail1", joints: ["tail1", "tail2"] }];
  const on = { chains, on: true, stiffness: 1, drag: 0.4, gravity: 9.81 };
  assert.deepEqual(withSprings(graph, on), {
    layers: [{ graph: "g1" }],
    springs: [{ name: "tail1", joints: ["tail1", "tail2"], stiffness: 1, drag: 0.4, gravity: [0, -9.81, 0] }],
  });
  assert.equal(withSprings(graph, { ...on, on: false }), graph);
  assert.equal(withSprings(graph, { ...on, chains: [] }), graph);
  assert.deepEqual(graph, { layers: [{ graph: "g1" }] }, "the motion given is left as it was");
});
