// A plain Node `ws` broadcaster: the peer the server's broadcasts are measured against
// (bench/broadcast_peer.sh, BENCHMARKS.md "Broadcasts against a Node `ws` peer").
//
// It speaks just enough of the broadcast API (docs/broadcasts.md) for `inbetween load ws-broadcast` to drive it
// unchanged, and does per tick only what any broadcaster must: stamp one frame, encode it once, and hand that one
// buffer to every viewer's socket with `ws`'s `send`.
//
//   POST /v1/clips                   201 {"id"}: the load generator uploads its clip first; it is not kept
//   POST /v1/broadcasts              201, the summary of docs/broadcasts.md; starts the broadcast's ticks at `fps`
//   GET  /v1/broadcasts/{id}         the summary
//   GET  /v1/broadcasts/{id}/stream  WebSocket (JSON text frames only), the grid phase in `inbetween-grid-phase-ms`
//   DELETE /v1/broadcasts/{id}       204; every viewer gets close 1000 "the broadcast ended"
//   GET  /metrics                    inbetween_broadcasts_total, inbetween_broadcast_ticks_total, and the frames
//                                    slow viewers lost, peer_viewer_frames_dropped_total
//   gRPC /inbetween.v1.Animation/Ping on its own HTTP/2 port: the load generator syncs its clock with it
//
// The frame is a real one, read from `--frame` (bench/peer_ws_broadcast/capture.mjs takes it from the server):
// every byte is sent as it came except the numbers of `seq`, `sent_at_unix_nanos` (stamped once per tick) and
// `dropped` (0: one buffer is shared by every viewer, so no viewer's own count is patched in). Tick `n` is due
// `n·10⁹/fps` ns after the process's clock origin, which `Ping` reports as its monotonic zero, and `seq` counts
// the broadcast's ticks from its creation, so the load generator measures lateness on the peer's grid as it does
// on the server's. A timer that wakes past a later tick skips to the latest due tick (the viewers see a gap); a
// viewer holding 8 frames unsent loses the tick's frame (the server's slow viewer keeps 8 and loses its oldest).
//
//   node server.mjs --frame frame.json    # prints "peer listening on http://…" and "peer gRPC listening on http://…"

import { readFileSync } from 'node:fs';
import { createServer } from 'node:http';
import { createServer as createH2Server } from 'node:http2';
import { randomUUID } from 'node:crypto';
import { parseArgs } from 'node:util';
import { WebSocketServer } from 'ws';

const { values: args } = parseArgs({ options: { frame: { type: 'string' } } });
if (!args.frame) throw new Error('--frame FILE is required (a JSON frame of the server, see capture.mjs)');

/** The frames a slow viewer may hold unsent before it loses one (docs/broadcasts.md). */
const VIEWER_QUEUE = 8;
/** The grid phase, in whole ms, of every broadcast here. */
const PHASE_MS = 0n;

// One clock: monotonic ns since the origin, and the wall clock as the origin's wall time plus that.
const originHr = process.hrtime.bigint();
const originUnixNs = BigInt(Math.round((performance.timeOrigin + performance.now()) * 1e6));
const monotonicNs = () => process.hrtime.bigint() - originHr;
const unixNs = (mono) => originUnixNs + mono;

/** The frame as pieces of text around its three header numbers, each hole a key of `stamp`. */
function template(text) {
  const head = text.indexOf(',"events":');
  if (head < 0) throw new Error('the frame has no "events" (a JSON frame of the server is needed)');
  const holes = ['seq', 'sent_at_unix_nanos', 'dropped'].map((key) => {
    const at = text.indexOf(`"${key}":`);
    if (at < 0 || at > head) throw new Error(`the frame has no "${key}" before "events"`);
    const start = at + key.length + 3;
    let end = start;
    while (end < head && /[-0-9]/.test(text[end])) end++;
    return { key, start, end };
  });
  holes.sort((a, b) => a.start - b.start);
  const pieces = [];
  let at = 0;
  for (const h of holes) {
    pieces.push(text.slice(at, h.start), h.key);
    at = h.end;
  }
  pieces.push(text.slice(at));
  return pieces;
}

const pieces = template(readFileSync(args.frame, 'utf8').trim());

/** One tick's frame, encoded once: `pieces` with the numbers filled in. */
function stamp(seq, sentAt) {
  const numbers = { seq: String(seq), sent_at_unix_nanos: String(sentAt), dropped: '0' };
  let text = '';
  for (let i = 0; i < pieces.length; i++) text += i % 2 === 1 ? numbers[pieces[i]] : pieces[i];
  return Buffer.from(text);
}

const broadcasts = new Map();
let created = 0;
let ticksTotal = 0;
let droppedTotal = 0;

/** The ns of grid tick `n` at `fps` after the origin. */
const due = (fps, n) => PHASE_MS * 1_000_000n + (n * 1_000_000_000n) / BigInt(fps);

/** The last grid tick at `fps` due at or before monotonic `t`. */
function tickAtOrBefore(fps, t) {
  let n = ((t - PHASE_MS * 1_000_000n) * BigInt(fps)) / 1_000_000_000n;
  if (n < 0n) n = 0n;
  while (n > 0n && due(fps, n) > t) n--;
  while (due(fps, n + 1n) <= t) n++;
  return n;
}

/** Starts a broadcast's ticks: tick 0 is the first grid tick after now. */
function start(b) {
  b.first = tickAtOrBefore(b.fps, monotonicNs()) + 1n;
  b.next = b.first;
  schedule(b);
}

/** Sleeps until the next tick is due (never fires it early: its frame would sit on the tick before). */
function schedule(b) {
  const wait = due(b.fps, b.next) - monotonicNs();
  b.timer = setTimeout(() => tick(b), Math.max(1, Number((wait + 999_999n) / 1_000_000n)));
}

/** Sends the latest due tick's frame to every viewer, then sleeps until the next. */
function tick(b) {
  const now = monotonicNs();
  if (now < due(b.fps, b.next)) return schedule(b);
  const n = tickAtOrBefore(b.fps, now);
  const frame = stamp(n - b.first, unixNs(monotonicNs()));
  const full = VIEWER_QUEUE * frame.length;
  for (const ws of b.viewers) {
    if (ws.readyState !== ws.OPEN) continue;
    if (ws.bufferedAmount >= full) droppedTotal++;
    else ws.send(frame, { binary: false });
  }
  ticksTotal += Number(n + 1n - b.next);
  b.next = n + 1n;
  if (b.viewers.size > 0) b.idleSince = now;
  else if (now - b.idleSince > BigInt(b.idleTimeoutSecs) * 1_000_000_000n) return end(b);
  schedule(b);
}

/** Ends a broadcast: its ticks stop, its viewers are closed with 1000. */
function end(b) {
  clearTimeout(b.timer);
  broadcasts.delete(b.id);
  for (const ws of b.viewers) ws.close(1000, 'the broadcast ended');
}

/** The broadcast's summary, in the fields of the server's (docs/broadcasts.md). */
function summary(b) {
  const seq = tickAtOrBefore(b.fps, monotonicNs()) - b.first;
  return {
    id: b.id, fps: b.fps, seq: Number(seq < 0n ? 0n : seq), created_at: b.createdAt, state: 'playing', speed: 1.0,
    viewers: b.viewers.size, idle_timeout_secs: b.idleTimeoutSecs, grid_phase_ms: Number(PHASE_MS),
    stream: `/v1/broadcasts/${b.id}/stream`, motion: b.motion, space: 'local', joints: null,
  };
}

/** A JSON answer; problems in the server's shape. */
function reply(res, status, body, headers = {}) {
  const type = status >= 400 ? 'application/problem+json' : 'application/json';
  res.writeHead(status, { 'content-type': type, ...headers });
  res.end(body === undefined ? undefined : JSON.stringify(body));
}

const problem = (status, code, detail) => ({ type: 'about:blank', status, code, detail });

/** The request's body as JSON (undefined when it is not). */
async function jsonBody(req) {
  const chunks = [];
  for await (const c of req) chunks.push(c);
  try {
    return JSON.parse(Buffer.concat(chunks).toString('utf8'));
  } catch {
    return undefined;
  }
}

/** `POST /v1/broadcasts`: `fps` 1..=240 (default 30), `idle_timeout_secs` (default 300). */
async function create(req, res) {
  const body = await jsonBody(req);
  if (!body || typeof body !== 'object') return reply(res, 400, problem(400, 'bad_json', 'a JSON object'));
  const fps = body.fps ?? 30;
  if (!Number.isInteger(fps) || fps < 1 || fps > 240) {
    return reply(res, 422, problem(422, 'fps_out_of_range', 'fps must be 1..=240'));
  }
  const b = {
    id: randomUUID(), fps, motion: body.motion ?? null, createdAt: new Date().toISOString(),
    idleTimeoutSecs: body.idle_timeout_secs ?? 300, viewers: new Set(), idleSince: monotonicNs(),
  };
  broadcasts.set(b.id, b);
  created++;
  start(b);
  reply(res, 201, summary(b), { location: `/v1/broadcasts/${b.id}` });
}

const http = createServer(async (req, res) => {
  const url = new URL(req.url, 'http://peer');
  const id = url.pathname.match(/^\/v1\/broadcasts\/([^/]+)$/)?.[1];
  if (req.method === 'POST' && url.pathname === '/v1/clips') {
    for await (const _ of req);
    return reply(res, 201, { id: `peer-clip-${randomUUID()}` });
  }
  if (req.method === 'POST' && url.pathname === '/v1/broadcasts') return create(req, res);
  if (req.method === 'GET' && url.pathname === '/metrics') {
    res.writeHead(200, { 'content-type': 'text/plain; version=0.0.4' });
    const lines = [`inbetween_broadcasts_total ${created}`, `inbetween_broadcast_ticks_total ${ticksTotal}`,
      `peer_viewer_frames_dropped_total ${droppedTotal}`];
    return res.end(`${lines.join('\n')}\n`);
  }
  const b = id && broadcasts.get(id);
  if (id && !b) return reply(res, 404, problem(404, 'broadcast_not_found', `no broadcast ${id}`));
  if (b && req.method === 'GET') return reply(res, 200, summary(b));
  if (b && req.method === 'DELETE') {
    end(b);
    return reply(res, 204);
  }
  reply(res, 404, problem(404, 'not_found', `the peer has no ${req.method} ${url.pathname}`));
});

const wss = new WebSocketServer({ noServer: true, perMessageDeflate: false, clientTracking: false });
wss.on('headers', (headers) => headers.push(`inbetween-grid-phase-ms: ${PHASE_MS}`));

/** Refuses an upgrade with a plain HTTP answer. */
function refuse(socket, status, text) {
  socket.end(`HTTP/1.1 ${status} ${text}\r\nconnection: close\r\ncontent-length: 0\r\n\r\n`);
}

http.on('upgrade', (req, socket, head) => {
  const url = new URL(req.url, 'http://peer');
  const id = url.pathname.match(/^\/v1\/broadcasts\/([^/]+)\/stream$/)?.[1];
  const b = id && broadcasts.get(id);
  if (!b) return refuse(socket, 404, 'Not Found');
  if ((url.searchParams.get('encoding') ?? 'json') !== 'json') return refuse(socket, 400, 'Bad Request');
  wss.handleUpgrade(req, socket, head, (ws) => {
    if (!broadcasts.has(b.id)) return ws.close(1000, 'the broadcast ended');
    b.viewers.add(ws);
    ws.on('close', () => b.viewers.delete(ws));
    ws.on('error', () => b.viewers.delete(ws));
  });
});

/** A protobuf varint of a non-negative BigInt. */
function varint(v) {
  const out = [];
  while (v >= 0x80n) {
    out.push(Number(v & 0x7fn) | 0x80);
    v >>= 7n;
  }
  out.push(Number(v));
  return out;
}

/** `PingResponse{server_unix_nanos = 1, server_monotonic_nanos = 2}` in a gRPC message. */
function pingResponse() {
  const mono = monotonicNs();
  const message = Buffer.from([0x08, ...varint(unixNs(mono)), 0x10, ...varint(mono)]);
  const prefix = Buffer.alloc(5);
  prefix.writeUInt32BE(message.length, 1);
  return Buffer.concat([prefix, message]);
}

const grpc = createH2Server();
grpc.on('stream', (stream, headers) => {
  if (headers[':path'] !== '/inbetween.v1.Animation/Ping') {
    stream.respond({ ':status': 200, 'content-type': 'application/grpc', 'grpc-status': '12' }, { endStream: true });
    return;
  }
  stream.resume();
  stream.on('end', () => {
    stream.respond({ ':status': 200, 'content-type': 'application/grpc' }, { waitForTrailers: true });
    stream.on('wantTrailers', () => stream.sendTrailers({ 'grpc-status': '0' }));
    stream.end(pingResponse());
  });
});

http.listen(0, '127.0.0.1', () => {
  grpc.listen(0, '127.0.0.1', () => {
    // Both lines at once, after both listeners are bound (as the server prints its own).
    process.stdout.write(
      `peer listening on http://127.0.0.1:${http.address().port}\n` +
        `peer gRPC listening on http://127.0.0.1:${grpc.address().port}\n`,
    );
  });
});
process.on('SIGTERM', () => process.exit(0));
