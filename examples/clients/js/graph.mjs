#!/usr/bin/env node
// Drives a graph (docs/graphs.md) live, with nothing but the platform: fetch
// stores the graph, the standard WebSocket streams it, and each key press (or
// each second of a scripted loop) becomes a `set` control.
//
//   node examples/clients/js/graph.mjs --file examples/graphs/fox-locomotion.json
//     keys: ↑/↓ the first float parameter (±10 % of its range), 1–9 the triggers,
//     b toggles the first bool, q quits
//   node examples/clients/js/graph.mjs --file … --script   # no keyboard: a loop that checks what it reads
//   … --import examples/gltf/Fox/Fox.glb                   # imports the clips first (again: new versions)
//
// The file's clips may be named `name:X` (looked up on the server, as
// docs/graphs.md's worked example does with sed); the graph is stored under
// its name (a new version if the name is taken) and streamed with its report.
// `--script` walks the first float parameter from its minimum to its maximum
// in ten steps, a second each, and exits non-zero unless every blend1d over it
// shows the weights docs/graphs.md defines from the frame after each `set`.
// Node 22+, or Node 20 with --experimental-websocket.
import { readFile } from "node:fs/promises";
import { parseArgs } from "node:util";

const { values: opts } = parseArgs({
  options: {
    http: { type: "string", default: "http://127.0.0.1:8080" },
    token: { type: "string" },
    file: { type: "string" },
    import: { type: "string" },
    fps: { type: "string", default: "30" },
    script: { type: "boolean", default: false },
  },
});
if (!opts.file) throw new Error("usage: graph.mjs [--http URL] [--token T] [--script] --file GRAPH.json");
if (typeof WebSocket === "undefined") throw new Error("no WebSocket: use Node 22+ or --experimental-websocket");
const auth = opts.token ? { Authorization: `Bearer ${opts.token}` } : {};
const fps = Number(opts.fps);

async function call(path, init = {}) {
  const res = await fetch(`${opts.http}${path}`, { ...init, headers: { "Content-Type": "application/json", ...auth, ...init.headers } });
  const body = await res.json();
  if (!res.ok) throw new Error(`${path}: ${res.status} ${JSON.stringify(body)}`);
  return body;
}

/** The graph document with each `"clip": "name:X"` replaced by X's id. */
async function withClipIds(doc) {
  const ids = new Map();
  const walk = async (value) => {
    if (Array.isArray(value)) for (const v of value) await walk(v);
    else if (value && typeof value === "object") {
      for (const [key, v] of Object.entries(value)) {
        if (key === "clip" && typeof v === "string" && v.startsWith("name:")) {
          const name = v.slice(5);
          if (!ids.has(name)) {
            const { clips } = await call(`/v1/clips?name=${encodeURIComponent(name)}`);
            if (clips.length !== 1) throw new Error(`${clips.length} clips are named ${name}: import it first`);
            ids.set(name, clips[0].id);
          }
          value[key] = ids.get(name);
        } else await walk(v);
      }
    }
  };
  await walk(doc);
  return doc;
}

/** The weights a blend1d gives its points at `v` (docs/graphs.md, “Nodes”). */
export function blend1d(points, v) {
  const ats = points.map((p) => p.at);
  const w = ats.map(() => 0);
  if (v <= ats[0]) w[0] = 1;
  else if (v >= ats.at(-1)) w[w.length - 1] = 1;
  else {
    const i = ats.findIndex((at, k) => v >= at && v < ats[k + 1]);
    const u = (v - ats[i]) / (ats[i + 1] - ats[i]);
    [w[i], w[i + 1]] = [1 - u, u];
  }
  return w;
}

if (opts.import) {
  const body = await readFile(opts.import);
  const imported = await call("/v1/clips/import?replace=true", { method: "POST", body, headers: { "Content-Type": "application/octet-stream" } });
  console.error(`imported ${imported.clips.map((c) => c.name).join(", ")}`);
}
const doc = await withClipIds(JSON.parse(await readFile(opts.file, "utf8")));
const stored = await call("/v1/graphs?replace=true", { method: "POST", body: JSON.stringify(doc) });
const params = Object.entries(doc.parameters ?? {});
const [float, spec] = params.find(([, p]) => p.type === "float") ?? [];
const triggers = params.filter(([, p]) => p.type === "trigger").map(([name]) => name);
const [bool] = params.find(([, p]) => p.type === "bool") ?? [];
const blends = Object.entries(doc.nodes).filter(([, n]) => n.blend1d?.parameter === float);
console.error(`graph ${stored.name} ${stored.id} v${stored.version}: ${params.map(([n, p]) => `${n} (${p.type})`).join(", ")}`);

const ws = new WebSocket(`${opts.http.replace(/^http/, "ws")}/v1/stream`);
const settings = Object.fromEntries(params.filter(([, p]) => p.type !== "trigger").map(([n, p]) => [n, p.default ?? (p.type === "bool" ? false : 0)]));
let pending = null; // {value, before, seq}: the last set, the value before it and the frame last read when it was sent
let checked = 0, failures = 0, states = new Set();

function set(parameters) {
  Object.assign(settings, parameters);
  ws.send(JSON.stringify({ op: "set", parameters }));
}

function check(frame) {
  const report = frame.graph ?? frame.pose.graph;
  if (!report) return;
  states.add(report.state);
  if (!pending) return;
  // A set lands on the tick after the server reads it: frames already on their way show the value before.
  const settled = frame.seq > pending.seq + fps / 2;
  const values = settled ? [pending.value] : [pending.value, pending.before];
  for (const [node, n] of blends) {
    const got = report.weights[node];
    if (!got) continue; // not playing this tick
    const off = (v) => Math.max(...got.map((w, i) => Math.abs(w - blend1d(n.blend1d.points, v)[i])));
    checked += 1;
    if (values.every((v) => off(v) > 1e-6)) failures += 1, console.error(`seq ${frame.seq}: ${node} [${got}] where ${float} = ${values.join(" or ")}`);
  }
}

function line(frame) {
  const r = frame.graph ?? frame.pose.graph ?? {};
  const t = r.transition ? ` ${r.transition.from}→${r.transition.to} α=${r.transition.alpha.toFixed(2)}` : "";
  const w = Object.entries(r.weights ?? {}).map(([n, ws]) => ` ${n}=[${ws.map((x) => x.toFixed(2))}]`).join("");
  return `seq=${frame.seq} ${float ?? ""}=${settings[float] ?? ""} state=${r.state}${t}${w}`;
}

function keys() {
  const step = ((spec?.max ?? 1) - (spec?.min ?? 0)) / 10;
  process.stdin.setRawMode(true);
  process.stdin.on("data", (data) => {
    const key = data.toString();
    if (key === "q" || key === "\u0003") return ws.send(JSON.stringify({ op: "stop" }));
    if (float && (key === "\u001b[A" || key === "\u001b[B")) {
      const v = settings[float] + (key === "\u001b[A" ? step : -step);
      set({ [float]: Math.min(spec.max, Math.max(spec.min, Math.round(v * 1e6) / 1e6)) });
    }
    if (bool && key === "b") set({ [bool]: !settings[bool] });
    const trigger = triggers[Number(key) - 1];
    if (trigger) set({ [trigger]: true });
  });
}

/** Ten steps of the first float, a second each, then stop. */
function script() {
  if (!float) throw new Error("--script walks a float parameter; the graph has none");
  let step = 0;
  const timer = setInterval(() => {
    if (step > 10) return clearInterval(timer), ws.send(JSON.stringify({ op: "stop" }));
    const value = spec.min + ((spec.max - spec.min) * step) / 10;
    pending = { value, before: settings[float], seq: lastSeq };
    set({ [float]: value });
    step += 1;
  }, 1000);
}

let lastSeq = -1;
ws.onopen = () => ws.send(JSON.stringify({ op: "open", motion: { layers: [{ graph: stored.id }] }, fps, report: true }));
ws.onmessage = (msg) => {
  const frame = JSON.parse(msg.data);
  if (frame.error) throw new Error(JSON.stringify(frame.error));
  if (frame.opened) return opts.script ? script() : keys();
  lastSeq = frame.seq;
  check(frame);
  if (!opts.script || frame.seq % fps === 0) console.log(line(frame));
};
ws.onclose = (e) => {
  if (process.stdin.isTTY && !opts.script) process.stdin.setRawMode(false);
  if (opts.script) {
    console.error(`${checked} reports checked against blend1d, ${failures} off; states seen: ${[...states].join(", ")}`);
    if (failures || !checked || states.size < 2) process.exit(1);
  }
  process.exit(e.code === 1000 ? 0 : 1);
};
