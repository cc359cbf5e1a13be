// The three.js adapter without a browser: decoded compact frames of a test
// vector (docs/compact-frames/) land on the bones of the same names. The bones
// here are plain objects with the part of three's Object3D the adapter uses
// (no three in the CI's node); with three installed, its real bones too.
// Run: node --test examples/clients/js/tests/
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { fileURLToPath } from "node:url";
import { join, dirname } from "node:path";

import { CompactDecoder, fromHex } from "../compact.mjs";
import { BonePoser, bonesByName, flatten } from "../three-bones.mjs";

const vector = JSON.parse(
  readFileSync(join(dirname(fileURLToPath(import.meta.url)), "../../../../docs/compact-frames/bench20.json"), "utf8"),
);

class Triple {
  constructor(...v) {
    this.v = v;
  }
  set(...v) {
    this.v = v;
    return this;
  }
}

/** What the adapter touches of a three.js Bone: name, isBone, traverse, and the TRS `set`s. */
class Bone {
  constructor(name, isBone = true) {
    Object.assign(this, { name, isBone, children: [] });
    this.position = new Triple(0, 0, 0);
    this.quaternion = new Triple(0, 0, 0, 1);
    this.scale = new Triple(1, 1, 1);
  }
  add(child) {
    this.children.push(child);
    return child;
  }
  traverse(f) {
    f(this);
    for (const c of this.children) c.traverse(f);
  }
}

/** A scene of the vector's joints as a chain, but: one joint missing, one extra bone, one mesh named like a joint. */
function scene(names) {
  const root = new Bone("Scene", false);
  let parent = root;
  for (const name of names.slice(0, -1).reverse()) parent = parent.add(new Bone(name));
  root.add(new Bone("extra"));
  root.add(new Bone(names[0], false));
  return root;
}

test("decoded frames land on the bones of the same names, and nowhere else", () => {
  const decoder = new CompactDecoder(vector.layout);
  const names = decoder.names;
  const root = scene(names);
  const poser = BonePoser.forObject(root, names);
  assert.deepEqual(poser.missing, [names.at(-1)]);
  const bones = bonesByName(root);
  assert.equal(bones.get(names[0]).isBone, true, "the bone, not the mesh of the same name");
  for (const frame of vector.frames) {
    const decoded = decoder.decode(fromHex(frame.hex));
    assert.equal(poser.apply(decoded), names.length - 1);
    names.slice(0, -1).forEach((name, j) => {
      const bone = bones.get(name);
      // The stored pose of the vector, independent of the decoder's arrays.
      const want = frame.pose;
      assert.deepEqual(bone.position.v, want.translations[j].map(Math.fround), `${name} position`);
      assert.deepEqual(bone.quaternion.v, want.rotations[j].map(Math.fround), `${name} rotation`);
      assert.deepEqual(bone.scale.v, want.scales[j].map(Math.fround), `${name} scale`);
    });
  }
  assert.deepEqual(bones.get("extra").quaternion.v, [0, 0, 0, 1], "a bone without a joint is left alone");
});

test("a THREE.Skeleton's bone array binds as well as a scene", () => {
  const names = ["hips", "spine"];
  const bones = [new Bone("spine"), new Bone("hips")];
  const poser = new BonePoser(bones, names);
  const frame = flatten([
    { name: "hips", translation: [1, 2, 3], rotation: [0, 0, 0.6, 0.8], scale: [1, 1, 1] },
    { name: "spine", translation: [0, 0.5, 0], rotation: [0.6, 0, 0, 0.8], scale: [2, 2, 2] },
  ]);
  assert.equal(poser.apply(frame), 2);
  assert.deepEqual(bones[1].position.v, [1, 2, 3]);
  assert.deepEqual(bones[0].quaternion.v, [Math.fround(0.6), 0, 0, Math.fround(0.8)]);
  assert.deepEqual(bones[0].scale.v, [2, 2, 2]);
});

test("with three.js installed, its own bones take the frames", async (t) => {
  let THREE;
  try {
    THREE = await import("three");
  } catch {
    t.skip("three is not installed here (npm install three to run this)");
    return;
  }
  const decoder = new CompactDecoder(vector.layout);
  const bones = decoder.names.map((name) => Object.assign(new THREE.Bone(), { name }));
  bones.slice(1).forEach((b, i) => bones[i].add(b));
  const skeleton = new THREE.Skeleton(bones);
  const poser = new BonePoser(skeleton.bones, decoder.names);
  const frame = vector.frames[0];
  poser.apply(decoder.decode(fromHex(frame.hex)));
  bones.forEach((b, j) => {
    assert.deepEqual(b.position.toArray(), frame.pose.translations[j].map(Math.fround));
    assert.deepEqual(b.quaternion.toArray(), frame.pose.rotations[j].map(Math.fround));
  });
});
