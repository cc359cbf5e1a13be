// Compact frames (docs/compact-frames.md): a decoder for the binary frames of
// `encoding=compact` streams. No dependencies; runs in Node and browsers.
//
//   import { CompactDecoder } from "./compact.mjs";
//   const decoder = new CompactDecoder(opened.compact); // the stream's `opened` message
//   const frame = decoder.decode(new Uint8Array(message)); // frame.rotations, ...
//
// A decoder keeps the last key frame's values, so feed it every frame of one
// stream in order. A new layout mid-stream (a text message `{"layout", "seq"}`
// on a WebSocket, a later `compact_layout` on gRPC) goes to
// `decoder.relayout(layout)` before the frame after it, a key frame. The pose arrays it returns are reused by the next decode:
// copy them to keep them.

const KEY_FRAME = 1;
const EVENTS = 2; // an events section follows the body
const ROOT_MOTION = 4; // a root motion section follows the body (and the events)
const GRAPH = 8; // a graph report section follows (after the root motion)
const KNOWN_FLAGS = KEY_FRAME | EVENTS | ROOT_MOTION | GRAPH;
// Per joint in the value store: largest index, three rotation components,
// translation x y z, scale x y z.
const STRIDE = 10;

/** Why bytes are not a compact frame of a layout; `code` is stable. */
export class CompactError extends Error {
  constructor(code, message) {
    super(message);
    this.name = "CompactError";
    this.code = code;
  }
}

/** One quantised value: `min + (u * (max - min)) / n` in doubles. */
function field(bits, min, max) {
  return { bits, min, span: max - min, levels: 2 ** bits - 1 };
}

function valueOf(f, u) {
  return f.bits === 0 ? f.min : f.min + (u * f.span) / f.levels;
}

function compileJoint(joint) {
  const r = joint.rotation;
  const axes = (a) => [0, 1, 2].map((k) => field(a.bits[k], a.min[k], a.max[k]));
  const compiled = { translation: axes(joint.translation), scale: axes(joint.scale) };
  if (r.constant) {
    compiled.constant = r.constant;
  } else {
    const s = r.smallest_three;
    compiled.largest = s.largest; // null: sent per frame
    compiled.components = [0, 1, 2, 3].map((k) => field(s.bits[k], s.min[k], s.max[k]));
  }
  compiled.animated =
    !compiled.constant || [...compiled.translation, ...compiled.scale].some((f) => f.bits > 0);
  return compiled;
}

/** Reads bit fields packed least significant bit first. */
class BitReader {
  constructor(bytes, start) {
    this.bytes = bytes;
    this.bit = start * 8;
    this.end = bytes.length * 8;
  }

  read(bits) {
    if (bits === 0) return 0;
    if (this.bit + bits > this.end) throw new CompactError("compact_truncated", "the frame ends before its joint values");
    const b = this.bytes;
    const i = this.bit >>> 3;
    const word = (b[i] | (b[i + 1] << 8) | (b[i + 2] << 16) | (b[i + 3] << 24)) >>> (this.bit & 7);
    this.bit += bits;
    // Widths are at most 24 bits and the shift at most 7: one 32-bit word holds them.
    return bits === 32 ? word >>> 0 : word & ((1 << bits) - 1);
  }
}

// A varint as a Number (exact below 2^53: seq, dropped and offsets are).
function readVarint(bytes, at, what) {
  let value = 0;
  let scale = 1;
  for (let n = 0; n < 10; n++) {
    if (at.i >= bytes.length) throw new CompactError("compact_truncated", `the frame ends before its ${what}`);
    const byte = bytes[at.i++];
    value += (byte & 0x7f) * scale;
    if ((byte & 0x80) === 0) return value;
    scale *= 128;
  }
  throw new CompactError("compact_varint_overflow", "a varint is longer than 64 bits");
}

// A zigzag varint as a BigInt (nanoseconds since 1970 exceed 2^53), built
// from two Numbers of at most 35 bits each.
function readZigzag(bytes, at) {
  let lo = 0;
  let hi = 0;
  let scale = 1;
  for (let n = 0; n < 10; n++) {
    if (at.i >= bytes.length) throw new CompactError("compact_truncated", "the frame ends before its sent_at");
    const byte = bytes[at.i++];
    if (n < 5) lo += (byte & 0x7f) * scale;
    else hi += (byte & 0x7f) * scale;
    if ((byte & 0x80) === 0) {
      const zz = (BigInt(hi) << 35n) | BigInt(lo);
      return (zz >> 1n) ^ -(zz & 1n);
    }
    scale = n === 4 ? 1 : scale * 128;
  }
  throw new CompactError("compact_varint_overflow", "a varint is longer than 64 bits");
}

/** Decodes one stream's compact frames against the layout of its `opened` message. */
export class CompactDecoder {
  constructor(layout) {
    this.relayout(layout);
  }

  /**
   * Decodes frames of `layout` from now on (docs/compact-frames.md, "A new
   * layout"): the last key frame is forgotten, so a delta frame before the
   * new layout's first key frame is refused. The pose arrays are new.
   */
  relayout(layout) {
    if (layout.version !== 1) throw new CompactError("compact_version", `layout version ${layout.version}`);
    this.layout = layout;
    this.joints = layout.joints.map(compileJoint);
    const n = this.joints.length;
    this.names = layout.joints.map((j) => j.name);
    this.events = layout.events ?? []; // the clip's events, which frames index
    this.graph = layout.graph ?? { states: [], nodes: [] }; // a graph stream's names, which reports index
    this.key = new Uint32Array(n * STRIDE);
    this.values = new Uint32Array(n * STRIDE);
    this.keySeq = null;
    this.translations = new Float32Array(n * 3);
    this.rotations = new Float32Array(n * 4);
    this.scales = new Float32Array(n * 3);
    // Little-endian f32 clip time (every platform JavaScript runs on is little-endian).
    this.clipFloat = new Float32Array(1);
    this.clipBytes = new Uint8Array(this.clipFloat.buffer);
  }

  /**
   * Decodes `bytes` (a Uint8Array). Returns the header and the pose:
   * `{seq, dropped, sentAtUnixNanos (BigInt), clipTime, key, keySeq,
   * translations, rotations, scales}` (flat Float32Arrays, 3/4/3 per joint),
   * `events` (the events crossed since the previous frame, in order:
   * `{index, time, name}`, index into the layout's `events`) and
   * `rootMotion` (`{delta, total}`, each `[x, y, z, yaw]`, or null) and
   * `graph` (a graph stream's report as a JSON frame's `graph` member
   * states it, `{state, transition?: {from, to, alpha}, weights: {node:
   * [w…]}}`, its numbers f32s; or null).
   */
  decode(bytes) {
    if (bytes.length === 0) throw new CompactError("compact_truncated", "the frame ends before its flags");
    const flags = bytes[0];
    if ((flags & ~KNOWN_FLAGS) !== 0) {
      throw new CompactError("compact_unknown_flags", `flags ${flags} use bits other than key frame, events, root motion and graph`);
    }
    const key = (flags & KEY_FRAME) !== 0;
    const at = { i: 1 };
    const seq = readVarint(bytes, at, "seq");
    const dropped = readVarint(bytes, at, "dropped");
    const keySeq = seq - readVarint(bytes, at, "key offset");
    const sentAtUnixNanos = readZigzag(bytes, at);
    if (at.i + 4 > bytes.length) throw new CompactError("compact_truncated", "the frame ends before its clip time");
    for (let k = 0; k < 4; k++) this.clipBytes[k] = bytes[at.i + k];
    const clipTime = this.clipFloat[0];
    const reader = new BitReader(bytes, at.i + 4);
    if (key) {
      this.readKey(reader);
      this.keySeq = seq;
    } else {
      if (this.keySeq !== keySeq) {
        throw new CompactError(
          "compact_missing_key_frame",
          `a delta frame refers to key frame ${keySeq}, and the last key frame seen is ${this.keySeq}`,
        );
      }
      this.readDelta(reader);
    }
    at.i += 4 + Math.ceil((reader.bit - (at.i + 4) * 8) / 8);
    const events = (flags & EVENTS) !== 0 ? this.readEvents(bytes, at) : [];
    const rootMotion = (flags & ROOT_MOTION) !== 0 ? readRootMotion(bytes, at) : null;
    const graph = (flags & GRAPH) !== 0 ? this.readGraph(bytes, at) : null;
    if (at.i !== bytes.length) {
      throw new CompactError("compact_trailing_bytes", `${bytes.length - at.i} bytes follow the frame's last field`);
    }
    this.dequantise();
    return {
      seq,
      dropped,
      sentAtUnixNanos,
      clipTime,
      key,
      keySeq,
      translations: this.translations,
      rotations: this.rotations,
      scales: this.scales,
      events,
      rootMotion,
      graph,
    };
  }

  // The graph report section: the state, the transition (0, or from + 1, to
  // and alpha), then each evaluated blend node's index and weights.
  readGraph(bytes, at) {
    const { states, nodes } = this.graph;
    const index = (list, what) => {
      const i = readVarint(bytes, at, "graph report");
      if (i >= list.length) {
        throw new CompactError("compact_unknown_graph_index", `graph ${what} ${i} is not in the layout's ${list.length}`);
      }
      return i;
    };
    const report = { state: states[index(states, "state")] };
    const from = readVarint(bytes, at, "graph report");
    if (from !== 0) {
      if (from - 1 >= states.length) {
        throw new CompactError("compact_unknown_graph_index", `graph state ${from - 1} is not in the layout's ${states.length}`);
      }
      const to = states[index(states, "state")];
      report.transition = { from: states[from - 1], to, alpha: readF32s(bytes, at, 1)[0] };
    }
    report.weights = {};
    const count = readVarint(bytes, at, "graph report");
    for (let n = 0; n < count; n++) {
      const node = nodes[index(nodes, "node")];
      report.weights[node.name] = readF32s(bytes, at, node.points);
    }
    return report;
  }

  // The events section: a count, then indices into the layout's `events`.
  readEvents(bytes, at) {
    const count = readVarint(bytes, at, "events");
    const events = [];
    for (let n = 0; n < count; n++) {
      const index = readVarint(bytes, at, "events");
      if (index >= this.events.length) {
        throw new CompactError("compact_unknown_event", `event ${index} is not in the layout's ${this.events.length} events`);
      }
      events.push({ index, time: this.events[index].time, name: this.events[index].name });
    }
    return events;
  }

  readKey(reader) {
    for (let j = 0; j < this.joints.length; j++) this.readJoint(reader, j);
    this.key.set(this.values);
  }

  readDelta(reader) {
    this.values.set(this.key);
    for (let j = 0; j < this.joints.length; j++) {
      if (this.joints[j].animated && reader.read(1) === 1) this.readJoint(reader, j);
    }
  }

  readJoint(reader, j) {
    const joint = this.joints[j];
    const v = this.values;
    const o = j * STRIDE;
    if (joint.components) {
      const largest = joint.largest ?? reader.read(2);
      v[o] = largest;
      for (let k = 0, slot = 1; k < 4; k++) {
        if (k !== largest) v[o + slot++] = reader.read(joint.components[k].bits);
      }
    }
    for (let a = 0; a < 3; a++) v[o + 4 + a] = reader.read(joint.translation[a].bits);
    for (let a = 0; a < 3; a++) v[o + 7 + a] = reader.read(joint.scale[a].bits);
  }

  dequantise() {
    const v = this.values;
    const small = [0, 0, 0];
    for (let j = 0; j < this.joints.length; j++) {
      const joint = this.joints[j];
      const o = j * STRIDE;
      const r = j * 4;
      if (joint.constant) {
        for (let k = 0; k < 4; k++) this.rotations[r + k] = joint.constant[k];
      } else {
        const largest = v[o];
        for (let k = 0, slot = 0; k < 4; k++) {
          if (k !== largest) {
            small[slot] = valueOf(joint.components[k], v[o + 1 + slot]);
            slot++;
          }
        }
        const sum = small[0] * small[0] + small[1] * small[1] + small[2] * small[2];
        let big = 0;
        if (sum < 1) {
          big = Math.sqrt(1 - sum);
        } else {
          const norm = Math.sqrt(sum);
          for (let s = 0; s < 3; s++) small[s] = small[s] / norm;
        }
        for (let k = 0, slot = 0; k < 4; k++) this.rotations[r + k] = k === largest ? big : small[slot++];
      }
      for (let a = 0; a < 3; a++) {
        this.translations[j * 3 + a] = valueOf(joint.translation[a], v[o + 4 + a]);
        this.scales[j * 3 + a] = valueOf(joint.scale[a], v[o + 7 + a]);
      }
    }
  }
}

// The root motion section: delta then total, each x, y, z, yaw as little-endian f32s.
function readRootMotion(bytes, at) {
  if (at.i + 32 > bytes.length) throw new CompactError("compact_truncated", "the frame ends before its root motion");
  const view = new DataView(bytes.buffer, bytes.byteOffset + at.i, 32);
  const values = Array.from({ length: 8 }, (_, k) => view.getFloat32(4 * k, true));
  at.i += 32;
  return { delta: values.slice(0, 4), total: values.slice(4) };
}

// `count` little-endian f32s of the graph report section.
function readF32s(bytes, at, count) {
  if (at.i + 4 * count > bytes.length) throw new CompactError("compact_truncated", "the frame ends before its graph report");
  const view = new DataView(bytes.buffer, bytes.byteOffset + at.i, 4 * count);
  at.i += 4 * count;
  return Array.from({ length: count }, (_, k) => view.getFloat32(4 * k, true));
}

/** `"0a1b..."` → Uint8Array, for test vectors. */
export function fromHex(hex) {
  const out = new Uint8Array(hex.length / 2);
  for (let i = 0; i < out.length; i++) out[i] = parseInt(hex.slice(2 * i, 2 * i + 2), 16);
  return out;
}
