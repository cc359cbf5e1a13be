#!/usr/bin/env node
// A JavaScript client of inbetween with nothing but the platform: fetch for
// REST and the standard WebSocket for a stream (Node 22+, or Node 20 with
// --experimental-websocket; the same code runs in a browser page).
//
//   node examples/clients/js/play.mjs --http http://127.0.0.1:8080 examples/wave.json
//   node --experimental-websocket examples/clients/js/play.mjs …   # on Node 20
//
// Uploads the clip, plays it at 30 fps in model space, seeks half-way through
// after 10 frames, and prints each frame; exits non-zero when a frame breaks
// the schedule (docs/api.md, streaming) or the seek does not land.
import { readFile } from "node:fs/promises";
import { parseArgs } from "node:util";

const { values: opts, positionals } = parseArgs({
  allowPositionals: true,
  options: {
    http: { type: "string", default: "http://127.0.0.1:8080" },
    token: { type: "string" },
    fps: { type: "string", default: "30" },
    frames: { type: "string", default: "20" },
  },
});
if (positionals.length !== 1) throw new Error("usage: play.mjs [--http URL] [--token T] CLIP.json");
if (typeof WebSocket === "undefined") throw new Error("no WebSocket: use Node 22+ or --experimental-websocket");
const fps = Number(opts.fps);
const auth = opts.token ? { Authorization: `Bearer ${opts.token}` } : {};

/** POSTs the clip document (again: a new version of the clip of its name);
 * a problem body (RFC 9457) says why when it fails. */
async function upload(path) {
  const res = await fetch(`${opts.http}/v1/clips?replace=true`, {
    method: "POST",
    headers: { "Content-Type": "application/json", ...auth },
    body: await readFile(path),
  });
  const body = await res.json();
  if (!res.ok) throw new Error(`upload: ${res.status} ${JSON.stringify(body)}`);
  return body;
}

/** Resolves with the frames read; rejects on a broken schedule or an error message. */
function play(clip) {
  const url = `${opts.http.replace(/^http/, "ws")}/v1/clips/${clip.id}/stream?fps=${fps}&start=${clip.start}&playback=loop&space=model`;
  const ws = new WebSocket(url); // browsers cannot send headers: use a read-only token via a same-origin proxy
  const seekTo = clip.start + clip.duration / 2;
  let seekSeq = null;
  const frames = [];
  return new Promise((resolve, reject) => {
    ws.onerror = (e) => reject(new Error(`websocket: ${e.message ?? "error"}`));
    ws.onclose = (e) => (e.code === 1000 ? resolve(frames) : reject(new Error(`closed ${e.code} ${e.reason}`)));
    ws.onmessage = (msg) => {
      const frame = JSON.parse(msg.data);
      if (frame.error) return reject(new Error(JSON.stringify(frame.error)));
      frames.push(frame);
      const [x, y, z] = frame.pose.joints.at(-1).translation;
      console.log(`seq=${frame.seq} clip_time=${frame.clip_time.toFixed(4)} dropped=${frame.dropped} ` +
        `events=[${frame.events.map((e) => e.name)}] ${frame.pose.joints.at(-1).name}=[${x.toFixed(3)},${y.toFixed(3)},${z.toFixed(3)}]`);
      if (frame.seq === 10) {
        ws.send(JSON.stringify({ op: "seek", time: seekTo }));
        seekSeq = frame.seq;
      } else if (seekSeq === null) {
        const expected = clip.start + ((frame.seq / fps) % clip.duration);
        if (Math.abs(frame.clip_time - expected) > 1e-4) reject(new Error(`seq ${frame.seq}: clip time ${frame.clip_time}, expected ${expected}`));
      }
      if (frames.length === Number(opts.frames)) ws.send(JSON.stringify({ op: "stop" }));
    };
  });
}

const clip = await upload(positionals[0]);
console.log(`uploaded "${clip.name}" as ${clip.id}: ${clip.joints} joints, ${clip.start}..${clip.end} s`);
const frames = await play(clip);
// The seek acts on a following tick: from then on clip time runs from the seek target.
const after = frames.filter((f) => f.seq > 10);
const landed = after.find((f) => Math.abs(f.clip_time - (clip.start + clip.duration / 2)) < 0.5 / fps + 1e-4);
if (!landed) throw new Error("the seek never showed in the frames");
console.log(`seek landed on seq ${landed.seq}; ${frames.length} frames, stopped with 1000`);
