// Unit tests of the library's pure parts (../library.js: the filter, the
// names shared, the short id) and of the view's framing (../scene.js): `node --test`.
import { test } from "node:test";
import assert from "node:assert/strict";

import { matches, nameCounts, shortId } from "../library.js";
import { bounds, fitDistance } from "../scene.js";

const walk = { name: "Walk", tags: ["locomotion", "fox"] };
const wave = { name: "arm-wave", tags: [] };

test("the filter matches a name or a tag, any case; tag:x asks for the tag exactly", () => {
  assert.equal(matches(walk, ""), true);
  assert.equal(matches(walk, "  wal "), true);
  assert.equal(matches(walk, "LOCO"), true);
  assert.equal(matches(wave, "loco"), false);
  assert.equal(matches(walk, "tag:fox"), true);
  assert.equal(matches(walk, "tag:fo"), false);
  assert.equal(matches(walk, "tag: Locomotion"), true);
  assert.equal(matches({ name: "x" }, "tag:fox"), false, "a summary without tags");
});

test("names carried by more than one clip are counted", () => {
  const counts = nameCounts([{ name: "wave" }, { name: "arm-wave" }, { name: "wave" }, { name: "wave" }]);
  assert.deepEqual([...counts], [["wave", 3], ["arm-wave", 1]]);
});

test("a short id is the id's end: UUIDv7s made together share their start", () => {
  assert.equal(shortId("01a236dd-fc84-742e-8eb2-6b77af84a6e2"), "…af84a6e2");
  assert.equal(shortId("abc"), "abc");
});

test("framing: a sphere fits nine tenths of a 45° view's height", () => {
  const b = bounds([[0, 0, 0], [0, 1.8, 0], [0.4, 0.9, -0.2]]);
  assert.deepEqual(b.center, [0.2, 0.9, -0.1]);
  assert.ok(Math.abs(b.radius - Math.hypot(0.4, 1.8, 0.2) / 2) < 1e-12);
  // At distance d the view is 2·d·tan(22.5°) high; the sphere's 2r is 0.9 of that.
  const d = fitDistance(1);
  assert.ok(Math.abs(2 / (2 * d * Math.tan(Math.PI / 8)) - 0.9) < 1e-12);
  assert.equal(bounds([]), null);
});
