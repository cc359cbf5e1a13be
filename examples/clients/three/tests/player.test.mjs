// Name matching and the three.js player without a browser: the player takes
// a compact stream's `opened` message and frames of a test vector
// (docs/compact-frames/) from a stand-in socket and puts the interpolated
// pose on stand-in nodes with the part of three's Object3D it uses.
// Run: node --test examples/clients/three/tests/
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { fileURLToPath } from "node:url";
import { join, dirname } from "node:path";

import { fromHex } from "../../js/compact.mjs";
import { InbetweenPlayer, nodesOf, streamUrl } from "../inbetween-three.mjs";
import { godotName, matchNames, threeName } from "../names.mjs";

test("names as three.js and Godot rewrite them", () => {
  assert.equal(threeName("mixamorig:Hips"), "mixamorigHips");
  assert.equal(threeName("Left Arm.001[2]/x"), "Left_Arm0012x");
  assert.equal(godotName("mixamorig:Hips"), "mixamorig_Hips");
  assert.equal(godotName("a/b:c d"), "a_b_c d");
});

test("a joint binds to its exact name first, then to its rewritten name, else to nothing", () => {
  const joints = ["mixamorig:Hips", "mixamorig:Spine", "Tail", "b_Root_00"];
  const nodes = ["Scene", "mixamorigSpine", "mixamorig:Spine", "mixamorigHips", "b_Root_00", "b_Root_00"];
  assert.deepEqual(matchNames(joints, nodes), [3, 2, -1, 4]);
  assert.deepEqual(matchNames(["mixamorig:Hips"], ["mixamorig_Hips"], godotName), [0]);
  assert.deepEqual(matchNames(["mixamorig:Hips"], ["mixamorig_Hips"]), [-1], "three's rule is not Godot's");
});

test("stream URLs carry the clip and the query", () => {
  assert.equal(
    streamUrl("ws://127.0.0.1:8080/", "a b", { fps: 20, encoding: "compact" }),
    "ws://127.0.0.1:8080/v1/clips/a%20b/stream?fps=20&encoding=compact",
  );
});

class Triple {
  constructor(...v) {
    this.v = v;
  }
  set(...v) {
    this.v = v;
    return this;
  }
  clone() {
    return new Triple(...this.v);
  }
  get x() {
    return this.v[0];
  }
  get y() {
    return this.v[1];
  }
  get z() {
    return this.v[2];
  }
  /** A quaternion's `q · this`. */
  premultiply(q) {
    const [ax, ay, az, aw] = q.v;
    const [bx, by, bz, bw] = this.v;
    return this.set(
      aw * bx + ax * bw + ay * bz - az * by,
      aw * by - ax * bz + ay * bw + az * bx,
      aw * bz + ax * by - ay * bx + az * bw,
      aw * bw - ax * bx - ay * by - az * bz,
    );
  }
}

/** What the player touches of a three.js Object3D. */
class Node {
  constructor(name, isBone) {
    Object.assign(this, { name, isBone, children: [] });
    this.position = new Triple(0, 0, 0);
    this.quaternion = new Triple(0, 0, 0, 1);
    this.scale = new Triple(1, 1, 1);
  }
  traverse(f) {
    f(this);
    for (const c of this.children) c.traverse(f);
  }
}

const vector = JSON.parse(
  readFileSync(join(dirname(fileURLToPath(import.meta.url)), "../../../../docs/compact-frames/bench20.json"), "utf8"),
);

test("bones come before other nodes of the same name; a skinned mesh offers its skeleton's bones", () => {
  const root = new Node("root", false);
  const mesh = new Node("j0", false);
  const bone = new Node("j0", true);
  root.children.push(mesh, bone);
  assert.deepEqual(
    nodesOf(root).map((n) => [n.name, n.isBone]),
    [
      ["j0", true],
      ["root", false],
      ["j0", false],
    ],
  );
  assert.deepEqual(nodesOf({ isSkinnedMesh: true, skeleton: { bones: [bone] } }), [bone]);
});

test("a compact stream's frames land on the nodes, interpolated at the render time", () => {
  const names = vector.layout.joints.map((j) => j.name);
  // A plain Object3D hierarchy (no bones), one joint missing.
  const root = new Node("character", false);
  root.children = names.slice(1).map((name) => new Node(name, false));
  const socket = {};
  const player = new InbetweenPlayer(socket, { fps: 30, target: root });
  socket.onmessage({ data: JSON.stringify({ opened: { compact: vector.layout } }) });
  assert.deepEqual(player.missing, ["j0"]);
  assert.equal(player.update(0), null, "nothing to show before a frame");
  // Frames seq 7, 8, 9 arriving exactly on time from t = 1 s: seq 7 at 1000 ms.
  const { frames } = vector;
  frames.forEach((f) => player.receive(fromHex(f.hex).buffer, 1000 + ((f.seq - 7) * 1000) / 30));
  // Render time at 1000 + 2 ticks + half a tick: halfway between seq 7 and seq 8.
  const shown = player.update(1000 + 2.5 * (1000 / 30));
  assert.deepEqual([shown.mode, shown.from.seq, shown.to.seq], ["interpolate", 7, 8]);
  assert.ok(Math.abs(shown.alpha - 0.5) < 1e-9, `${shown.alpha}`);
  const [a, b] = [frames[0].pose, frames[1].pose];
  names.slice(1).forEach((name, i) => {
    const j = i + 1;
    const node = root.children[i];
    const mid = a.translations[j].map((x, k) => (Math.fround(x) + Math.fround(b.translations[j][k])) / 2);
    node.position.v.forEach((x, k) => assert.ok(Math.abs(x - mid[k]) < 1e-6, `${name} translation ${x} ${mid[k]}`));
    // Halfway along the arc: the normalised sum of the two (same-hemisphere) quaternions.
    const qa = a.rotations[j].map(Math.fround);
    const qb0 = b.rotations[j].map(Math.fround);
    const dot = qa.reduce((s, x, k) => s + x * qb0[k], 0);
    const qb = dot < 0 ? qb0.map((x) => -x) : qb0;
    const sum = qa.map((x, k) => x + qb[k]);
    const n = Math.hypot(...sum);
    node.quaternion.v.forEach((x, k) => assert.ok(Math.abs(x - sum[k] / n) < 1e-6, `${name} rotation`));
  });
  assert.equal(player.frames, 3);
  assert.ok(player.bytes > 0);
});

test("a compact stream's events reach onevents and its root motion moves the target", () => {
  const stepping = JSON.parse(
    readFileSync(join(dirname(fileURLToPath(import.meta.url)), "../../../../docs/compact-frames/stepping.json"), "utf8"),
  );
  const target = new Node("character", false);
  target.children = [new Node("spinner", true)];
  const socket = {};
  const player = new InbetweenPlayer(socket, { fps: 30, target });
  const heard = [];
  player.onevents = (events, frame) => heard.push(...events.map((e) => [frame.seq, e.name]));
  socket.onmessage({ data: JSON.stringify({ opened: { compact: stepping.layout } }) });
  stepping.frames.forEach((f) => player.receive(fromHex(f.hex).buffer, 1000 + ((f.seq - 7) * 1000) / 30));
  assert.deepEqual(heard, [
    [7, "step_left"],
    [9, "step_right"],
    [9, "land"],
  ]);
  // Exactly on seq 8's time: its total, [0.05, 0, -0.125] travelled and 0.1 rad about +Y.
  player.update(1000 + 3 * (1000 / 30));
  const total = stepping.frames[1].root_motion.total.map(Math.fround);
  target.position.v.forEach((x, k) => assert.ok(Math.abs(x - total[k]) < 1e-6, `position ${k}: ${x}`));
  const [, y, , w] = target.quaternion.v;
  assert.ok(Math.abs(y - Math.sin(total[3] / 2)) < 1e-6 && Math.abs(w - Math.cos(total[3] / 2)) < 1e-6);
});

test("a new layout mid-stream decodes on, and the pose interpolates across it without a jump", () => {
  const vector = JSON.parse(
    readFileSync(join(dirname(fileURLToPath(import.meta.url)), "../../../../docs/compact-frames/relayout.json"), "utf8"),
  );
  const target = new Node("character", false);
  const spinner = new Node("spinner", true);
  target.children = [spinner];
  const socket = {};
  const player = new InbetweenPlayer(socket, { fps: 30, target });
  socket.onmessage({ data: JSON.stringify({ opened: { compact: vector.layout } }) });
  const at = (f) => 1000 + ((f.seq - 7) * 1000) / 30;
  for (const f of vector.frames) {
    if (f.layout) socket.onmessage({ data: JSON.stringify({ layout: f.layout, seq: f.seq }) });
    player.receive(fromHex(f.hex).buffer, at(f));
  }
  assert.equal(player.frames, 4);
  assert.equal(player.error, null);
  // Halfway between seq 8 (the old layout's last frame) and seq 9 (the new one's key frame), two ticks behind.
  player.update(at(vector.frames[1]) + 2 * (1000 / 30) + 500 / 30);
  const [a, b] = [vector.frames[1].pose.translations[0], vector.frames[2].pose.translations[0]];
  spinner.position.v.forEach((x, k) => assert.ok(Math.abs(x - (a[k] + b[k]) / 2) < 1e-6, `position ${k}: ${x}`));
});
