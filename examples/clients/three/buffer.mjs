// Snapshot interpolation for an inbetween stream: frames arrive at the
// stream's rate (20 a second, say) with network jitter; a game renders at 60
// Hz. The buffer keeps the last few frames and shows the pose at a render
// time a little behind the newest frame (two ticks by default), interpolated
// between the two frames around it: translations and scales lerped, rotations
// slerped. When the next frame is late the pose is extrapolated from the last
// two frames for at most one tick, then held until frames come again.
//
// No dependencies and no three.js: the pose goes into flat Float64Arrays
// (3 translation, 4 rotation [x, y, z, w], 3 scale values per joint) that an
// adapter puts on whatever the engine has.
//
// Stream time: frame `seq` of a stream at `fps` is due at `seq / fps` seconds
// after the first (docs/api.md, Streams), whatever the clip does (a paused or
// seeking stream still ticks), so interpolation runs on `seq`, never on the
// clip time.

/** How far the clock estimate may rise per second of arrivals (a network that got slower for good). */
const CLOCK_CREEP = 0.001;

/** Writes `a + (b - a) t` for `n` values from `ao` and `bo` into `out` from `oo`. */
export function lerp(out, oo, a, ao, b, bo, n, t) {
  for (let k = 0; k < n; k++) out[oo + k] = a[ao + k] + (b[bo + k] - a[ao + k]) * t;
}

/**
 * Spherical interpolation of the unit quaternions at `a[ao..ao+4]` and
 * `b[bo..bo+4]` ([x, y, z, w]) into `out[oo..oo+4]`, along the shorter arc
 * (`q` and `-q` are one rotation; a stream may send either). `t` outside
 * [0, 1] extrapolates along the same arc.
 */
export function slerp(out, oo, a, ao, b, bo, t) {
  let dot = a[ao] * b[bo] + a[ao + 1] * b[bo + 1] + a[ao + 2] * b[bo + 2] + a[ao + 3] * b[bo + 3];
  const sign = dot < 0 ? -1 : 1;
  dot *= sign;
  let wa;
  let wb;
  if (dot > 1 - 1e-9) {
    // Nearly the same rotation: the arc is a line (sin θ would divide by ~0).
    wa = 1 - t;
    wb = t;
  } else {
    const theta = Math.acos(dot);
    const sin = Math.sin(theta);
    wa = Math.sin((1 - t) * theta) / sin;
    wb = Math.sin(t * theta) / sin;
  }
  wb *= sign;
  for (let k = 0; k < 4; k++) out[oo + k] = wa * a[ao + k] + wb * b[bo + k];
  if (dot > 1 - 1e-9) normalise(out, oo);
}

function normalise(q, o) {
  const n = Math.hypot(q[o], q[o + 1], q[o + 2], q[o + 3]);
  for (let k = 0; k < 4; k++) q[o + k] /= n;
}

/** One frame's pose, copied out of the decoder's reused arrays. */
function snapshot(frame, fps) {
  return {
    seq: frame.seq,
    time: frame.seq / fps,
    clipTime: frame.clipTime,
    translations: Float64Array.from(frame.translations),
    rotations: Float64Array.from(frame.rotations),
    scales: Float64Array.from(frame.scales),
    // Root motion's running total [x, y, z, yaw] when the stream carries it (JSON motion streams).
    root: frame.root ? Float64Array.from(frame.root) : null,
  };
}

/** The pose a sample writes: flat Float64Arrays for `joints` joints. */
export function emptyPose(joints) {
  return {
    translations: new Float64Array(joints * 3),
    rotations: new Float64Array(joints * 4),
    scales: new Float64Array(joints * 3),
    root: new Float64Array(4),
    hasRoot: false,
  };
}

/** The last frames of one stream, and the pose between them at a render time. */
export class SnapshotBuffer {
  /**
   * `fps`: the stream's rate. `delayTicks`: how far behind the newest frame
   * the render time runs (2: one late frame still arrives in time).
   * `capacity`: frames kept.
   */
  constructor({ fps, delayTicks = 2, capacity = 8 }) {
    if (!(fps > 0)) throw new RangeError(`fps must be positive, not ${fps}`);
    Object.assign(this, { fps, tick: 1 / fps, delay: delayTicks / fps, capacity });
    this.frames = [];
    this.offset = null; // arrival clock minus stream time, seconds: the smallest lateness seen
    this.lastArrival = null;
  }

  /** Keeps `frame` (a decoded frame: `seq`, pose arrays, optional `root`), which arrived at `arrivalMs`. */
  push(frame, arrivalMs) {
    const shot = snapshot(frame, this.fps);
    const newest = this.frames.at(-1);
    if (newest && shot.seq <= newest.seq) {
      // A new stream (seq starts again): forget the old one's frames and clock.
      this.frames.length = 0;
      this.offset = null;
    }
    this.frames.push(shot);
    if (this.frames.length > this.capacity) this.frames.shift();
    this.observe(arrivalMs / 1000, shot.time);
  }

  /** The clock estimate: the least lateness seen, rising slowly so a lasting slow-down is followed. */
  observe(arrival, streamTime) {
    const lateness = arrival - streamTime;
    const crept = this.offset === null ? lateness : this.offset + CLOCK_CREEP * (arrival - this.lastArrival);
    this.offset = Math.min(lateness, crept);
    this.lastArrival = arrival;
  }

  /** The stream time to show at `nowMs` (same clock as `push`), or null before the first frame. */
  renderTime(nowMs) {
    return this.offset === null ? null : nowMs / 1000 - this.offset - this.delay;
  }

  /**
   * Writes the pose at stream time `time` into `out` (`emptyPose`). Returns
   * what it did: `{mode, from, to, alpha}` with `mode` one of `interpolate`
   * (between `from` and `to`), `extrapolate` (past the newest, at most a tick),
   * `hold` (further past it, or before the oldest, or only one frame), or
   * null when there is no frame yet.
   */
  sample(time, out) {
    const frames = this.frames;
    if (frames.length === 0) return null;
    const newest = frames.at(-1);
    if (frames.length === 1 || time <= frames[0].time) {
      const only = time <= frames[0].time ? frames[0] : newest;
      this.blend(only, only, 0, out);
      return { mode: "hold", from: only, to: only, alpha: 0 };
    }
    if (time <= newest.time) {
      let i = frames.length - 1;
      while (frames[i - 1].time > time) i--;
      const [from, to] = [frames[i - 1], frames[i]];
      const alpha = (time - from.time) / (to.time - from.time);
      this.blend(from, to, alpha, out);
      return { mode: "interpolate", from, to, alpha };
    }
    const from = frames.at(-2);
    const limit = newest.time + this.tick;
    const alpha = (Math.min(time, limit) - from.time) / (newest.time - from.time);
    this.blend(from, newest, alpha, out);
    return { mode: time <= limit ? "extrapolate" : "hold", from, to: newest, alpha };
  }

  blend(a, b, t, out) {
    const joints = a.rotations.length / 4;
    for (let j = 0; j < joints; j++) {
      lerp(out.translations, 3 * j, a.translations, 3 * j, b.translations, 3 * j, 3, t);
      slerp(out.rotations, 4 * j, a.rotations, 4 * j, b.rotations, 4 * j, t);
      lerp(out.scales, 3 * j, a.scales, 3 * j, b.scales, 3 * j, 3, t);
    }
    out.hasRoot = Boolean(a.root && b.root);
    if (out.hasRoot) lerp(out.root, 0, a.root, 0, b.root, 0, 4, t);
  }
}
