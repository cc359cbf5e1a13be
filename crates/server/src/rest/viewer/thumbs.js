// A small picture of each clip for the library: its skeleton in the pose at
// the middle of its range (model space), seen from the front and a little
// to the side, fitted to the square. Made once per clip version: kept in
// memory and in IndexedDB (a clip's new version gets a new picture), and
// made two at a time so that a long list does not flood the server.

import { api } from "./api.js";
import { cameraBasis, toCamera, toScreen } from "./math.js";

const SIZE = 48;
const DB = "inbetween-viewer", STORE = "thumbnails";
const made = new Map(); // `${id}@${version}` → Promise of a data URL
const waiting = []; // thumbnails to make: () => Promise
let running = 0;
const AT_ONCE = 2;

/// Draws clip `clip`'s thumbnail on `canvas` (from the cache when it has one).
export async function thumbnail(clip, canvas) {
  const key = `${clip.id}@${clip.version}`;
  if (!made.has(key)) made.set(key, cached(key).then((url) => url || queued(() => render(clip)).then((u) => (store(key, u), u))));
  const url = await made.get(key).catch((e) => (made.delete(key), Promise.reject(e)));
  const image = new Image();
  image.src = url;
  await image.decode();
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.drawImage(image, 0, 0, canvas.width, canvas.height);
  canvas.dataset.thumb = key;
}

/// How many thumbnails this page made itself (not from the cache): read by the browser test.
export const stats = { rendered: 0, fromCache: 0 };

function queued(job) {
  return new Promise((resolve, reject) => {
    waiting.push(() => job().then(resolve, reject));
    pump();
  });
}

function pump() {
  while (running < AT_ONCE && waiting.length) {
    const job = waiting.shift();
    running += 1;
    job().finally(() => ((running -= 1), pump()));
  }
}

/// The picture: bones as lines, lit from the front.
async function render(clip) {
  const id = encodeURIComponent(clip.id);
  const mid = (clip.start + clip.end) / 2;
  const [skeleton, pose] = await Promise.all([api(`/v1/clips/${id}/skeleton`), api(`/v1/clips/${id}/pose?t=${mid}&space=model`)]);
  const at = new Map(pose.joints.map((j) => [j.name, j.translation]));
  const bones = skeleton.joints.filter((j) => j.parent != null && at.has(j.parent) && at.has(j.name)).map((j) => [at.get(j.parent), at.get(j.name)]);
  const points = [...at.values()];
  const lo = [0, 1, 2].map((k) => Math.min(...points.map((p) => p[k])));
  const hi = [0, 1, 2].map((k) => Math.max(...points.map((p) => p[k])));
  const target = lo.map((l, k) => (l + hi[k]) / 2);
  const radius = Math.max(Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2, 1e-3);
  const cam = cameraBasis({ yaw: 0.5, pitch: 0.15, dist: radius * 2.5, target }, SIZE * 2, SIZE * 2);
  const canvas = document.createElement("canvas");
  canvas.width = canvas.height = SIZE * 2;
  const ctx = canvas.getContext("2d");
  ctx.fillStyle = "#101216";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.strokeStyle = "#c8d0dc";
  ctx.lineWidth = 2.5;
  ctx.lineCap = "round";
  ctx.beginPath();
  for (const [a, b] of bones) {
    const p = toCamera(cam, a), q = toCamera(cam, b);
    if (p[2] <= cam.near || q[2] <= cam.near) continue;
    ctx.moveTo(...toScreen(cam, p));
    ctx.lineTo(...toScreen(cam, q));
  }
  ctx.stroke();
  stats.rendered += 1;
  return canvas.toDataURL("image/png");
}

// ---- IndexedDB: the pictures outlive the page ----

let db = null;
function open() {
  db ||= new Promise((resolve, reject) => {
    const request = indexedDB.open(DB, 1);
    request.onupgradeneeded = () => request.result.createObjectStore(STORE);
    request.onsuccess = () => resolve(request.result);
    request.onerror = () => reject(request.error);
  });
  return db;
}

async function cached(key) {
  try {
    const store = (await open()).transaction(STORE).objectStore(STORE);
    const url = await new Promise((resolve, reject) => {
      const request = store.get(key);
      request.onsuccess = () => resolve(request.result);
      request.onerror = () => reject(request.error);
    });
    if (url) stats.fromCache += 1;
    return url;
  } catch {
    return null; // no IndexedDB (a private window): make it
  }
}

async function store(key, url) {
  try {
    (await open()).transaction(STORE, "readwrite").objectStore(STORE).put(url, key);
  } catch {
    // Not kept: made again next time.
  }
}
