// Our retargeting against three.js's (docs/characters.md, "Agreement with three.js").
//
// The server imports a BVH take and a glTF character and plays the take on the character (a motion with
// `character`); three.js loads the same two files with its own BVHLoader and GLTFLoader and retargets the take
// with SkeletonUtils.retarget and retargetClip, its options set to our documented rule (below). Both answers are
// compared at every frame of the take: per target joint the model-space rotation (the angle between the two, in
// degrees) and the hips' model-space position. Exits 1 when a maximum is over its limit (`--max-deg` for
// `retarget` at the take's keys, `--max-deg-clip` for retargetClip, `--max-hips` for both; none by default).
//
//   node compare.mjs --http http://127.0.0.1:8080 --bvh take.bvh --gltf character.gltf \
//        [--max-deg 7e-5] [--max-deg-clip 1.5e-3] [--max-hips 1e-6] [--token TOKEN]
//
// The option mapping. Ours: a mapped target joint's model rotation is G_d(t) = G_s(t)·(G⁰_s)⁻¹·G⁰_d, the hips'
// model position p⁰_d + k·(p_s(t) − p⁰_s), every other joint keeps its reference local translation and unmapped
// joints their reference local rotation. three.js's `retarget` sets a mapped bone's world rotation to its source
// bone's times `localOffsets[bone]`, its world position (the hip's only, with `preserveBonePositions`) to
// `scale·(p_s(t) + hipPosition)`, and poses unmapped bones at the skin's bind pose. So:
//   names          target bone → source bone, from the roles both summaries report (three.js has no roles)
//   localOffsets   per mapped target bone, (G⁰_s)⁻¹·G⁰_d as a rotation matrix (three.js's default: none, which
//                  copies the source's world rotation as it is, right only when both rest poses are alike)
//   hip            the source's hips joint (default 'hip')
//   scale          k = h_d/h_s, the hips' heights above the lower foot in each reference (default 1)
//   hipPosition    p⁰_d/k − p⁰_s (default none: the target's hips would go where the source's are)
//   useFirstFramePosition false, preserveBonePositions true, preserveBoneMatrix true (the defaults)
// G⁰_d is three.js's own bind pose of the skin (Skeleton.pose()); G⁰_s the BVH's rest (no rotation) with the
// hips at their first frame's position, as the server's default `source_pose` documents.

import { readFileSync } from 'node:fs';
import { basename, extname } from 'node:path';
import { parseArgs } from 'node:util';
import { AnimationMixer, LoopOnce, Matrix4, Quaternion, SkeletonHelper, Vector3 } from 'three';
import { BVHLoader } from 'three/examples/jsm/loaders/BVHLoader.js';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { retarget, retargetClip } from 'three/examples/jsm/utils/SkeletonUtils.js';

const { values: args } = parseArgs({
  options: {
    http: { type: 'string' },
    bvh: { type: 'string' },
    gltf: { type: 'string' },
    token: { type: 'string' },
    'max-deg': { type: 'string', default: 'Infinity' },
    'max-deg-clip': { type: 'string', default: 'Infinity' },
    'max-hips': { type: 'string', default: 'Infinity' },
  },
});
for (const required of ['http', 'bvh', 'gltf']) {
  if (!args[required]) throw new Error(`--${required} is required (see the header of ${basename(import.meta.url)})`);
}
const limits = { deg: Number(args['max-deg']), degClip: Number(args['max-deg-clip']), hips: Number(args['max-hips']) };

/** A JSON request to the server; throws with the body on a status other than `expect`. */
async function call(method, path, body, expect, contentType = 'application/json') {
  const headers = { 'content-type': contentType };
  if (args.token) headers.authorization = `Bearer ${args.token}`;
  const payload = body === undefined || typeof body === 'string' || body instanceof Uint8Array ? body : JSON.stringify(body);
  const resp = await fetch(args.http + path, { method, headers, body: payload });
  const text = await resp.text();
  if (resp.status !== expect) throw new Error(`${method} ${path}: ${resp.status} ${text.slice(0, 500)}`);
  return JSON.parse(text);
}

/** Imports `file` at `route` under `name`, replacing an earlier import; the first summary of `list`. */
async function importFile(route, file, name, list, extra = '') {
  const query = `?name=${encodeURIComponent(name)}&replace=true${extra}`;
  const answer = await call('POST', route + query, readFileSync(file), 201, 'application/octet-stream');
  return answer[list][0];
}

/** role → joint name, from a character summary. */
const roleJoints = (summary) => Object.fromEntries(Object.entries(summary.roles).map(([r, v]) => [r, v.joint]));

// ---- The server's side.
const stem = basename(args.bvh, extname(args.bvh));
const character = await importFile('/v1/characters/import', args.gltf, 'peer-retarget/character', 'characters');
const take = await importFile('/v1/clips/import', args.bvh, `peer-retarget/${stem}`, 'clips', '&playback=once');
// The take's roles as the retargeter infers them: the same skeleton imported as a character reports them.
const takeRig = await importFile('/v1/characters/import', args.bvh, `peer-retarget/${stem}-rig`, 'characters');
const targetRoles = roleJoints(character);
const sourceRoles = roleJoints(takeRig);

// ---- three.js's side: its loaders read the same files.
const bvh = new BVHLoader().parse(readFileSync(args.bvh, 'utf8'));
const gltf = await parseGltf(args.gltf);
const mesh = findSkinnedMesh(gltf.scene);
nameNodesAsTheServer(gltf);
const scene = gltf.scene;
scene.updateMatrixWorld(true);

const names = {};
for (const [role, joint] of Object.entries(targetRoles)) {
  if (sourceRoles[role] !== undefined) names[joint] = sourceRoles[role];
}
const sourceHips = sourceRoles.hips;
const target = targetReference(mesh, scene);
const hipsHeight = target.position.hips.y - lowerFoot(target.position, targetRoles);
const frameTimes = bvh.clip.tracks[0].times; // f32 k·Frame Time, as the server's BVH import keys them

// Three runs of three.js over the take's frames:
// 1. `retarget` at each key time itself (the source posed by an AnimationMixer there, as retargetClip poses it),
//    against the server at the same f32 key times: both read the same keys, so what differs is the retarget.
// 2. The same with the source's reference at its first frame (`source_pose: {"time": 0}`, docs/motion.md's
//    example) instead of its rest.
// 3. `retargetClip` (its default fps: one frame per key), which samples the source at f·duration/(frames − 1)
//    accumulated in f64 (the last 10⁻⁷ s early), against the server at those times.
const atRest = plan(sourceReference(bvh, null), {});
const atFirst = plan(sourceReference(bvh, 0), { source_pose: { time: 0 } });
const keyLimit = { deg: limits.deg, hips: limits.hips };
const runs = [
  await compare('retarget at the keys, source_pose the rest', [...frameTimes], retargetAt(frameTimes, atRest), atRest,
    keyLimit),
  await compare('retarget at the keys, source_pose {"time": 0}', [...frameTimes], retargetAt(frameTimes, atFirst),
    atFirst, keyLimit),
];
const retargeted = retargetClip(mesh, bvh.skeleton, bvh.clip, { ...atRest.options });
const clipTimes = retargetClipTimes(bvh.clip, retargeted.tracks[0].times.length);
runs.push(await compare('retargetClip, source_pose the rest', clipTimes, (f) => poseTarget(mesh, retargeted, f), atRest,
  { deg: limits.degClip, hips: limits.hips }));
const failed = runs.includes(false);
console.log(failed ? 'FAILED: over a limit' : 'agreement within the limits');
process.exit(failed ? 1 : 0);

/** three.js's options for our rule (the header's mapping) from the source's reference `source`; `retarget` is
 *  the motion's `retarget` field that asks the server for the same reference. */
function plan(source, retarget) {
  const k = hipsHeight / (source.position[sourceHips].y - lowerFoot(source.position, sourceRoles));
  const localOffsets = {};
  for (const [targetBone, sourceBone] of Object.entries(names)) {
    const offset = source.rotation[sourceBone].clone().invert().multiply(target.rotation[targetBone]);
    localOffsets[targetBone] = new Matrix4().makeRotationFromQuaternion(offset);
  }
  const hipPosition = target.position.hips.clone().divideScalar(k).sub(source.position[sourceHips]);
  const options = { names, localOffsets, hip: sourceHips, scale: k, hipPosition, useFirstFramePosition: false };
  return { k, options, retarget };
}

/** Compares three.js's target, posed for frame `f` by `pose(f)`, with the server's poses at `times`; prints the
 *  figures and returns whether they are within `limit`. */
async function compare(label, times, pose, { k, retarget }, limit) {
  const ours = await serverPoses(times, retarget);
  const angles = [];
  const hipsOff = [];
  const worst = {};
  let turned = 0; // how far the server's poses turn a joint from the bind pose, and move the hips
  let travel = 0;
  const world = new Quaternion();
  const at = new Vector3();
  for (let f = 0; f < times.length; f++) {
    pose(f);
    scene.updateMatrixWorld(true);
    for (const joint of ours[f].joints) {
      const node = scene.getObjectByName(joint.name);
      if (!node) throw new Error(`three.js has no node '${joint.name}'`);
      const deg = angleDeg(node.getWorldQuaternion(world), joint.rotation);
      angles.push(deg);
      if (!(worst[joint.name]?.deg >= deg)) worst[joint.name] = { deg, frame: f };
      if (target.rotation[joint.name]) turned = Math.max(turned, angleDeg(target.rotation[joint.name], joint.rotation));
      if (joint.name === targetRoles.hips) {
        const [x, y, z] = joint.translation;
        node.getWorldPosition(at);
        hipsOff.push(Math.hypot(at.x - x, at.y - y, at.z - z));
        const [x0, y0, z0] = ours[0].joints.find((j) => j.name === joint.name).translation;
        travel = Math.max(travel, Math.hypot(x - x0, y - y0, z - z0));
      }
    }
  }
  const rotation = { max: Math.max(...angles), p99: percentile(angles, 0.99) };
  const hips = { max: Math.max(...hipsOff), p99: percentile(hipsOff, 0.99) };
  console.log(`== ${label}: take ${stem} (${times.length} frames) on ${basename(args.gltf)}, ` +
    `${ours[0].joints.length} joints, ${Object.keys(names).length} mapped, k = ${k.toFixed(6)}`);
  console.log(`  the server's poses turn joints up to ${turned.toFixed(1)}° from the bind pose and move the hips up to ` +
    `${travel.toFixed(3)}`);
  console.log('  per joint, the largest model-space rotation difference (degrees) and its frame:');
  for (const [name, w] of Object.entries(worst)) {
    const role = Object.entries(targetRoles).find(([, j]) => j === name)?.[0] ?? '(unmapped)';
    console.log(`    ${name.padEnd(8)} ${role.padEnd(14)} ${w.deg.toExponential(2)}  frame ${w.frame}`);
  }
  console.log(`  rotation: max ${rotation.max.toExponential(3)}°, p99 ${rotation.p99.toExponential(3)}° ` +
    `(limit ${limit.deg}°) over ${angles.length} joint-frames`);
  console.log(`  hips position: max ${hips.max.toExponential(3)}, p99 ${hips.p99.toExponential(3)} ` +
    `(limit ${limit.hips}; the character's units, its hips ${hipsHeight.toFixed(4)} above its feet)`);
  return rotation.max <= limit.deg && hips.max <= limit.hips;
}

/** Poses the target for frame `f` with three.js's `retarget`, the source posed by a mixer at `times[f]`. */
function retargetAt(times, { options }) {
  const helper = new SkeletonHelper(bvh.skeleton.bones[0]);
  helper.skeleton = bvh.skeleton;
  const mixer = new AnimationMixer(helper);
  mixer.clipAction(bvh.clip).setLoop(LoopOnce, 1).play().clampWhenFinished = true;
  return (f) => {
    mixer.setTime(times[f]);
    bvh.skeleton.bones[0].updateMatrixWorld(true);
    retarget(mesh, bvh.skeleton, { ...options });
  };
}

/** The source times retargetClip's mixer reached, frame by frame (its own arithmetic, see SkeletonUtils.js). */
function retargetClipTimes(clip, count) {
  const delta = clip.duration / (count - 1);
  const times = [0];
  for (let f = 0; f + 1 < count; f++) times.push(times[f] + (f === count - 2 ? delta - 0.0000001 : delta));
  return times;
}

// ---- Helpers.

/** three.js's GLTFLoader on the file, images and materials left out (decoding them needs a DOM; the skeleton
 *  and the skin do not). A `.gltf`'s `data:` buffers go into one GLB binary chunk, as its loader fetches URIs
 *  with browser events Node lacks; a `.glb` is read as it is. */
async function parseGltf(file) {
  const bytes = readFileSync(file);
  const glb = bytes.readUInt32LE(0) === 0x46546c67;
  const json = glb ? JSON.parse(bytes.subarray(20, 20 + bytes.readUInt32LE(12)).toString('utf8')) : JSON.parse(bytes);
  let bin = glb ? glbBinary(bytes) : Buffer.alloc(0);
  for (const key of ['images', 'textures', 'samplers', 'materials']) delete json[key];
  for (const m of json.meshes ?? []) for (const p of m.primitives) delete p.material;
  if (!glb) {
    const starts = [];
    for (const buffer of json.buffers ?? []) {
      const data = Buffer.from(buffer.uri.slice(buffer.uri.indexOf(',') + 1), 'base64');
      starts.push(bin.length);
      bin = Buffer.concat([bin, data, Buffer.alloc((4 - (data.length % 4)) % 4)]);
    }
    for (const view of json.bufferViews ?? []) {
      view.byteOffset = (view.byteOffset ?? 0) + starts[view.buffer];
      view.buffer = 0;
    }
    json.buffers = [{ byteLength: bin.length }];
  }
  const text = Buffer.from(JSON.stringify(json), 'utf8');
  const padded = Buffer.concat([text, Buffer.alloc((4 - (text.length % 4)) % 4, 0x20)]);
  const header = Buffer.alloc(12);
  header.writeUInt32LE(0x46546c67, 0);
  header.writeUInt32LE(2, 4);
  header.writeUInt32LE(12 + 8 + padded.length + 8 + bin.length, 8);
  const chunk = (type, data) => {
    const head = Buffer.alloc(8);
    head.writeUInt32LE(data.length, 0);
    head.writeUInt32LE(type, 4);
    return Buffer.concat([head, data]);
  };
  const out = Buffer.concat([header, chunk(0x4e4f534a, padded), chunk(0x004e4942, bin)]);
  const arrayBuffer = out.buffer.slice(out.byteOffset, out.byteOffset + out.length);
  return new Promise((resolve, reject) => new GLTFLoader().parse(arrayBuffer, '', resolve, reject));
}

/** A GLB's binary chunk (the one after its JSON chunk). */
function glbBinary(bytes) {
  const next = 20 + bytes.readUInt32LE(12);
  return bytes.subarray(next + 8, next + 8 + bytes.readUInt32LE(next));
}

function findSkinnedMesh(root) {
  let found = null;
  root.traverse((o) => { if (!found && o.isSkinnedMesh) found = o; });
  if (!found) throw new Error('the glTF has no skinned mesh');
  return found;
}

/** Names three.js's nodes as the server's import names joints: the node's name, else `node<index>`. */
function nameNodesAsTheServer(loaded) {
  const json = loaded.parser.json;
  for (const [object, where] of loaded.parser.associations) {
    if (where?.nodes === undefined || !object.isObject3D) continue;
    object.name = json.nodes[where.nodes].name || `node${where.nodes}`;
  }
}

/** The source's reference, world rotations and positions by bone name: at `time` of the take, else its rest
 *  (offsets, no rotation) with the root where the first frame puts it. */
function sourceReference({ skeleton, clip }, time) {
  const saved = skeleton.bones.map((b) => [b.position.clone(), b.quaternion.clone()]);
  const root = skeleton.bones[0];
  if (time === null) {
    root.position.fromArray(clip.tracks.find((t) => t.name === `${root.name}.position`).values, 0);
  } else {
    const helper = new SkeletonHelper(root);
    helper.skeleton = skeleton;
    const mixer = new AnimationMixer(helper);
    mixer.clipAction(clip).play();
    mixer.setTime(time); // left cached: uncaching would restore the bones' rest before they are read
  }
  root.updateMatrixWorld(true);
  const reference = worldOf(skeleton.bones);
  skeleton.bones.forEach((b, i) => { b.position.copy(saved[i][0]); b.quaternion.copy(saved[i][1]); });
  root.updateMatrixWorld(true);
  return reference;
}

/** The target's reference: the skin's bind pose as three.js restores it (Skeleton.pose()), in world space. */
function targetReference(skinned, root) {
  skinned.skeleton.pose();
  root.updateMatrixWorld(true);
  const reference = worldOf(skinned.skeleton.bones);
  reference.position.hips = reference.position[targetRoles.hips];
  return reference;
}

function worldOf(bones) {
  const rotation = {};
  const position = {};
  for (const bone of bones) {
    if (bone.name in rotation) continue; // the BVH's End Sites share one name; none is a role
    rotation[bone.name] = bone.getWorldQuaternion(new Quaternion());
    position[bone.name] = bone.getWorldPosition(new Vector3());
  }
  return { rotation, position };
}

/** The lower foot's height in a reference. */
function lowerFoot(position, roles) {
  const feet = ['leftFoot', 'rightFoot'].map((r) => roles[r]).filter((j) => j !== undefined);
  if (feet.length === 0) throw new Error('a rig without feet: k needs another measure');
  return Math.min(...feet.map((j) => position[j].y));
}

/** The server's model-space poses at `times` (one `POST /v1/samples`). */
async function serverPoses(times, retarget) {
  const motion = { layers: [{ clip: take.id }], character: character.id, retarget };
  const answer = await call('POST', '/v1/samples', { motion, times, space: 'model' }, 200);
  return answer.poses;
}

/** Sets the target's bones to frame `f` of the retargeted clip: its tracks, the bind pose elsewhere. */
function poseTarget(skinned, clip, f) {
  skinned.skeleton.pose();
  for (const track of clip.tracks) {
    const [, bone, property] = /^\.bones\[(.+)\]\.(position|quaternion)$/.exec(track.name);
    const node = skinned.skeleton.getBoneByName(bone);
    const size = property === 'position' ? 3 : 4;
    node[property].fromArray(track.values, f * size);
  }
}

/** The angle between two rotations, in degrees (`b` as `[x, y, z, w]`): of a⁻¹·b, by atan2, which keeps its
 *  precision near 0 (acos of the dot product loses it). */
function angleDeg(a, b) {
  const d = a.clone().invert().multiply(new Quaternion(b[0], b[1], b[2], b[3]).normalize());
  return (2 * Math.atan2(Math.hypot(d.x, d.y, d.z), Math.abs(d.w)) * 180) / Math.PI;
}

function percentile(values, q) {
  const sorted = [...values].sort((x, y) => x - y);
  return sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))];
}
