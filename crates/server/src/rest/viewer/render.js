// The page's one render loop: work is scheduled by name and done at the
// next animation frame (the display's rate), once however often it was
// asked for. Nothing is drawn per WebSocket message: a message only keeps
// the latest frame, and the loop shows it. Updates (the newest frame's
// pose) run before draws (scene, curves, playhead) in the same frame.

const updates = new Map(); // name → task, run first
const draws = new Map(); // name → task, run after the updates
const lastRun = new Map(); // name → when a throttled task last ran (ms)
let queued = false;
/// Animation frames can stall (a busy or hidden page): a timer then does the work.
const FALLBACK_MS = 250;
/// A hidden page (a background tab) gets no animation frames and slow
/// timers: it keeps its state current at once and draws when shown again.
const hidden = () => typeof document !== "undefined" && document.hidden;
if (typeof document !== "undefined") document.addEventListener("visibilitychange", () => hidden() || request());

/// Whether a task last run at `last` may run again at `now` (ms), at most
/// once per `interval`. Pure: the throttle's whole rule.
export const due = (last, now, interval) => last == null || now - last >= interval;

function request() {
  if (queued || typeof requestAnimationFrame !== "function" || hidden()) return;
  queued = true;
  requestAnimationFrame(tick);
  setTimeout(() => queued && tick(performance.now()), FALLBACK_MS);
}

function runAll(tasks, now) {
  for (const [name, task] of [...tasks]) {
    tasks.delete(name);
    task(now);
  }
}

function tick(now) {
  if (!queued) return; // the other of animation frame and fallback timer came first
  queued = false;
  runAll(updates, now);
  runAll(draws, now);
}

/// Runs `task` at the next animation frame, before any draw.
export function update(name, task) {
  if (hidden()) return task(performance.now());
  updates.set(name, task);
  request();
}

/// Draws with `task` at the next animation frame; with `interval` (ms), at
/// most that often (a later frame takes it when it comes too soon).
export function draw(name, task, interval = 0) {
  if (!interval) {
    draws.set(name, task);
    return request();
  }
  draws.set(name, (now) => {
    if (!due(lastRun.get(name), now, interval)) return draw(name, task, interval);
    lastRun.set(name, now);
    task(now);
  });
  request();
}
