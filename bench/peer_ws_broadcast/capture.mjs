// Takes one real broadcast frame from a running server for the peer (server.mjs --frame): creates a broadcast
// of the clip at `fps`, as `inbetween load ws-broadcast` does, watches it over the WebSocket (JSON frames),
// writes its second frame (a frame of a viewer that has been watching, not the first after joining) to `--out`,
// and deletes the broadcast.
//
//   node capture.mjs --http http://127.0.0.1:8080 --clip CLIP_ID --fps 30 --out frame.json

import { writeFileSync } from 'node:fs';
import { parseArgs } from 'node:util';
import WebSocket from 'ws';

const { values: args } = parseArgs({
  options: { http: { type: 'string' }, clip: { type: 'string' }, fps: { type: 'string' }, out: { type: 'string' } },
});
for (const required of ['http', 'clip', 'fps', 'out']) {
  if (!args[required]) throw new Error(`--${required} is required (see the header of capture.mjs)`);
}

/** How long the whole capture may take. */
const TIMEOUT_MS = 10_000;

const created = await fetch(`${args.http}/v1/broadcasts`, {
  method: 'POST',
  headers: { 'content-type': 'application/json' },
  body: JSON.stringify({ motion: { layers: [{ clip: args.clip }] }, fps: Number(args.fps), idle_timeout_secs: 60 }),
});
const summary = await created.json();
if (created.status !== 201) throw new Error(`creating the broadcast: ${created.status} ${JSON.stringify(summary)}`);

/** The second text message of the broadcast's stream. */
function secondFrame(url) {
  return new Promise((resolve, reject) => {
    const ws = new WebSocket(url);
    const timer = setTimeout(() => reject(new Error(`no second frame within ${TIMEOUT_MS} ms`)), TIMEOUT_MS);
    let seen = 0;
    ws.on('message', (data, binary) => {
      if (binary || ++seen < 2) return;
      clearTimeout(timer);
      ws.close();
      resolve(data.toString('utf8'));
    });
    ws.on('error', reject);
  });
}

try {
  const frame = await secondFrame(`${args.http.replace(/^http/, 'ws')}/v1/broadcasts/${summary.id}/stream`);
  writeFileSync(args.out, frame);
  console.log(`captured a ${Buffer.byteLength(frame)}-byte JSON frame of broadcast ${summary.id} into ${args.out}`);
} finally {
  await fetch(`${args.http}/v1/broadcasts/${summary.id}`, { method: 'DELETE' });
}
