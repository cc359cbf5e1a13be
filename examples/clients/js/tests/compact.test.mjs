// The JavaScript compact-frame decoder against docs/compact-frames/: every
// frame of every vector decodes to exactly the pose the Rust encoder
// quantised. Run: node --test examples/clients/js/tests/
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync, readdirSync } from "node:fs";
import { fileURLToPath } from "node:url";
import { join, dirname } from "node:path";

import { CompactDecoder, CompactError, fromHex } from "../compact.mjs";

const dir = join(dirname(fileURLToPath(import.meta.url)), "../../../../docs/compact-frames");
const vectors = readdirSync(dir)
  .filter((f) => f.endsWith(".json"))
  .map((f) => JSON.parse(readFileSync(join(dir, f), "utf8")));

const flat = (rows) => Float32Array.from(rows.flat());

test("there are vectors to read", () => {
  assert.ok(vectors.length >= 5, `${vectors.length} vectors in ${dir}`);
});

/** A vector's graph report (indices into the layout's `graph`) as a JSON frame names it, numbers as f32s. */
function named(graph, report) {
  const out = { state: graph.states[report.state] };
  const t = report.transition;
  if (t) out.transition = { from: graph.states[t.from], to: graph.states[t.to], alpha: Math.fround(t.alpha) };
  out.weights = Object.fromEntries(report.weights.map((w) => [graph.nodes[w.node].name, w.weights.map(Math.fround)]));
  return out;
}

for (const vector of vectors) {
  test(`${vector.name}: every frame decodes to the stored pose exactly`, () => {
    const decoder = new CompactDecoder(vector.layout);
    let layout = vector.layout;
    for (const frame of vector.frames) {
      // A new layout mid-stream (docs/compact-frames.md, "A new layout").
      if (frame.layout) decoder.relayout((layout = frame.layout));
      const got = decoder.decode(fromHex(frame.hex));
      assert.equal(got.key, frame.key);
      assert.equal(got.seq, frame.seq);
      assert.equal(got.dropped, frame.dropped);
      assert.equal(got.sentAtUnixNanos, BigInt(frame.sent_at_unix_nanos));
      assert.equal(got.clipTime, Math.fround(frame.clip_time));
      assert.deepEqual(got.rotations, flat(frame.pose.rotations));
      assert.deepEqual(got.translations, flat(frame.pose.translations));
      assert.deepEqual(got.scales, flat(frame.pose.scales));
      assert.deepEqual(got.events.map((e) => e.index), frame.events ?? []);
      for (const e of got.events) assert.equal(e.name, layout.events[e.index].name);
      const root = frame.root_motion;
      assert.deepEqual(got.rootMotion, root ? { delta: root.delta.map(Math.fround), total: root.total.map(Math.fround) } : null);
      assert.deepEqual(got.graph, frame.graph ? named(vector.layout.graph, frame.graph) : null);
    }
  });
}

test("a delta frame without its key frame is refused", () => {
  const vector = vectors.find((v) => v.name === "bench20");
  const decoder = new CompactDecoder(vector.layout);
  assert.throws(() => decoder.decode(fromHex(vector.frames[1].hex)), (e) => e instanceof CompactError && e.code === "compact_missing_key_frame");
  const key = fromHex(vector.frames[0].hex);
  assert.throws(() => decoder.decode(key.subarray(0, key.length - 1)), (e) => e.code === "compact_truncated");
  assert.throws(() => decoder.decode(Uint8Array.from([...key, 0])), (e) => e.code === "compact_trailing_bytes");
  assert.throws(() => decoder.decode(Uint8Array.from([16 | key[0], ...key.subarray(1)])), (e) => e.code === "compact_unknown_flags");
});

test("events past the layout's list and a root motion cut short are refused", () => {
  const vector = vectors.find((v) => v.name === "stepping");
  const key = fromHex(vector.frames[0].hex); // events [0], then root motion
  const at = key.length - 32 - 1; // the index
  assert.equal(key[at - 1], 1, "one event");
  const unknown = Uint8Array.from(key);
  unknown[at] = vector.layout.events.length;
  assert.throws(() => new CompactDecoder(vector.layout).decode(unknown), (e) => e.code === "compact_unknown_event");
  assert.throws(() => new CompactDecoder(vector.layout).decode(key.subarray(0, key.length - 1)), (e) => e.code === "compact_truncated");
});

test("a new layout forgets the old key frame", () => {
  const vector = vectors.find((v) => v.name === "relayout");
  const frames = vector.frames.map((f) => fromHex(f.hex));
  const decoder = new CompactDecoder(vector.layout);
  decoder.decode(frames[0]);
  decoder.decode(frames[1]);
  decoder.relayout(vector.frames[2].layout);
  assert.throws(() => decoder.decode(frames[3]), (e) => e.code === "compact_missing_key_frame");
  assert.equal(decoder.decode(frames[2]).key, true);
  assert.equal(decoder.decode(frames[3]).key, false);
});

test("a graph report's indices past the layout's graph and a report cut short are refused", () => {
  const vector = vectors.find((v) => v.name === "graph-report");
  const decoder = new CompactDecoder(vector.layout);
  decoder.decode(fromHex(vector.frames[0].hex)); // the key frame
  const delta = fromHex(vector.frames[1].hex); // state 2, transition 1 → 2, one node (docs/compact-frames.md)
  const at = delta.length - 4 - 4 - 1 - 1 - 4 - 1 - 1 - 1; // the state
  assert.equal(delta[at], 2);
  for (const [offset, value] of [[0, 3], [1, 4], [2, 3], [8, 2]]) {
    const bad = Uint8Array.from(delta);
    bad[at + offset] = value;
    assert.throws(() => decoder.decode(bad), (e) => e.code === "compact_unknown_graph_index", `byte ${offset} = ${value}`);
  }
  assert.throws(() => decoder.decode(delta.subarray(0, delta.length - 1)), (e) => e.code === "compact_truncated");
  const plain = { ...vector.layout, graph: undefined };
  assert.throws(() => new CompactDecoder(plain).decode(fromHex(vector.frames[0].hex)), (e) => e.code === "compact_unknown_graph_index");
});
