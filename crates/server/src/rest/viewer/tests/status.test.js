// Unit tests of what the header and status line say (../status.js) and of
// the render loop's throttle (../render.js): `node --test`.
import { test } from "node:test";
import assert from "node:assert/strict";

import { due } from "../render.js";
import { formatBytes, formatMs, formatSeconds, initialStatus, reduceStatus, statusView } from "../status.js";

const walk = { name: "Walk", joints: 24, start: 0, end: 0.7083333 };
const survey = { name: "Survey", joints: 24, start: 0, end: 3.4166667 };
const run = (...actions) => actions.reduce(reduceStatus, initialStatus);

test("seconds are rounded to the millisecond, trailing zeros dropped", () => {
  assert.equal(formatSeconds(0.7083333), "0.708");
  assert.equal(formatSeconds(0.7085), "0.709");
  assert.equal(formatSeconds(3), "3");
  assert.equal(formatSeconds(2.5), "2.5");
  assert.equal(formatSeconds(-0.0001), "0");
  assert.equal(formatSeconds(-1.23456), "-1.235");
  assert.equal(formatSeconds(1e-4), "0");
});

test("milliseconds keep a decimal only under 10 ms", () => {
  assert.equal(formatMs(0.96), "1.0 ms");
  assert.equal(formatMs(9.94), "9.9 ms");
  assert.equal(formatMs(12.5), "13 ms");
  assert.equal(formatMs(1234.4), "1234 ms");
});

test("selecting a clip names it in the header and says its range, rounded", () => {
  const view = statusView(run({ type: "select", clip: walk }));
  assert.deepEqual(view, { header: "paused: Walk", line: "Walk: 24 joints, 0–0.708 s", error: false });
});

test("an end is said until playing starts again, then never again", () => {
  const ended = run({ type: "select", clip: walk }, { type: "play" }, { type: "ended", time: 0.7083333 });
  assert.equal(statusView(ended).line, "Walk ended at 0.708 s — Play starts it over");
  assert.equal(statusView(ended).header, "ended: Walk");
  const again = reduceStatus(ended, { type: "play" });
  assert.equal(statusView(again).line, "Walk: 24 joints, 0–0.708 s");
  assert.equal(statusView(again).header, "playing: Walk");
  // Pausing after looping started does not bring the end back.
  assert.equal(statusView(reduceStatus(again, { type: "pause" })).line, "Walk: 24 joints, 0–0.708 s");
});

test("after a crossfade the header names the clip the frames show", () => {
  const s = run({ type: "select", clip: walk }, { type: "play" }, { type: "adopt", clip: survey });
  assert.equal(statusView(s).header, "playing: Survey");
  assert.equal(statusView(s).line, "Survey: 24 joints, 0–3.417 s");
});

test("a graph playing on a clip's skeleton is what the header names", () => {
  const s = run({ type: "select", clip: survey }, { type: "graph", name: "fox-locomotion" }, { type: "play" });
  assert.equal(statusView(s).header, "playing: graph fox-locomotion");
  assert.equal(statusView(s).line, "Survey: 24 joints, 0–3.417 s", "the skeleton's clip, for its joints and range");
  assert.equal(statusView(reduceStatus(s, { type: "graph", name: null })).header, "playing: Survey");
});

test("playing clears a message but keeps an error", () => {
  const info = run({ type: "select", clip: walk }, { type: "message", text: "event: step" }, { type: "play" });
  assert.equal(statusView(info).line, "Walk: 24 joints, 0–0.708 s");
  const error = run({ type: "select", clip: walk }, { type: "message", text: "refused", error: true }, { type: "play" });
  assert.deepEqual(statusView(error), { header: "playing: Walk", line: "refused", error: true });
  // A new selection starts with a clean line.
  assert.equal(statusView(reduceStatus(error, { type: "select", clip: survey })).error, false);
});

test("no clip: an empty header, the message alone", () => {
  assert.deepEqual(statusView(initialStatus), { header: "", line: "", error: false });
  assert.deepEqual(statusView(run({ type: "message", text: "listing clips" })), { header: "", line: "listing clips", error: false });
  assert.throws(() => reduceStatus(initialStatus, { type: "nonsense" }), /no status action/);
});

test("a throttled task runs at most once per interval", () => {
  assert.equal(due(undefined, 0, 33), true);
  assert.equal(due(100, 120, 33), false);
  assert.equal(due(100, 133, 33), true);
  // 60 animation frames a second through a 30-a-second throttle: every other frame runs.
  let last, runs = 0;
  for (let frame = 0; frame < 60; frame++) {
    const now = frame * (1000 / 60);
    if (due(last, now, 1000 / 30 - 1)) (last = now), (runs += 1);
  }
  assert.equal(runs, 30);
});

test("byte rates read as B/s, kB/s or MB/s, one decimal below 10", () => {
  assert.equal(formatBytes(0), "0 B/s");
  assert.equal(formatBytes(999), "999 B/s");
  assert.equal(formatBytes(3570), "3.6 kB/s");
  assert.equal(formatBytes(31410), "31 kB/s");
  assert.equal(formatBytes(2.5e6), "2.5 MB/s");
});
