// Puts decoded frames on a three.js skeleton: each joint's local translation,
// rotation and scale onto the bone of the same name, no AnimationMixer. No
// import of three itself: it uses only what every three.js `Object3D` has
// (`name`, `isBone`, `traverse`, and `set` on `position`, `quaternion` and
// `scale`), so it works with whatever copy of three the page loaded.
//
//   import { CompactDecoder } from "./compact.mjs";
//   import { BonePoser } from "./three-bones.mjs";
//   const decoder = new CompactDecoder(opened.compact);          // the `opened` message's layout
//   const poser = BonePoser.forObject(gltf.scene, decoder.names); // bones found by name, once
//   socket.onmessage = (m) => poser.apply(decoder.decode(new Uint8Array(m.data)));
//
// A frame is any object with flat `translations` (3 per joint), `rotations`
// (4, [x, y, z, w]) and `scales` (3) in the stream's joint order: a compact
// frame as `CompactDecoder` returns it, or a JSON frame's pose through
// `flatten`. The stream must be in local space (the default), which is what
// a bone's transform is.

/** Every bone under `root` (itself included), by name; the first of a repeated name wins. */
export function bonesByName(root) {
  const bones = new Map();
  root.traverse((node) => {
    if (node.isBone && !bones.has(node.name)) bones.set(node.name, node);
  });
  return bones;
}

/** Applies frames of a stream whose joints are `names` to the bones of the same names. */
export class BonePoser {
  /**
   * `bones`: a Map from name to bone (`bonesByName`), or an array of bones
   * (a `THREE.Skeleton`'s `bones`). Joints without a bone are skipped;
   * bones without a joint are left as they are.
   */
  constructor(bones, names) {
    const byName = bones instanceof Map ? bones : new Map(bones.map((b) => [b.name, b]));
    this.targets = [];
    this.missing = [];
    names.forEach((name, joint) => {
      const bone = byName.get(name);
      if (bone) this.targets.push({ joint, bone });
      else this.missing.push(name);
    });
  }

  /** A poser for the bones under `root` (a loaded glTF scene, a `SkinnedMesh`). */
  static forObject(root, names) {
    return new BonePoser(bonesByName(root), names);
  }

  /** Sets each bound bone's local transform from `frame`; returns how many bones it set. */
  apply(frame) {
    const { translations: t, rotations: r, scales: s } = frame;
    for (const { joint, bone } of this.targets) {
      bone.position.set(t[3 * joint], t[3 * joint + 1], t[3 * joint + 2]);
      bone.quaternion.set(r[4 * joint], r[4 * joint + 1], r[4 * joint + 2], r[4 * joint + 3]);
      bone.scale.set(s[3 * joint], s[3 * joint + 1], s[3 * joint + 2]);
    }
    return this.targets.length;
  }
}

/** A JSON frame's `pose.joints` (`[{name, translation, rotation, scale}]`) as flat arrays. */
export function flatten(joints) {
  return {
    translations: Float32Array.from(joints.flatMap((j) => j.translation)),
    rotations: Float32Array.from(joints.flatMap((j) => j.rotation)),
    scales: Float32Array.from(joints.flatMap((j) => j.scale)),
  };
}
