// What the header and the status line say, from one state object: the
// clip selected, the clip the frames show, whether it plays, paused or
// ended, and the last message. Pure (no DOM; unit-tested in tests/): a
// reducer of the page's happenings and the words they make.

export const initialStatus = Object.freeze({
  clip: null, // {name, joints, start, end} of the selected clip
  playing: null, // the name of the clip the view shows (a crossfade's after it)
  mode: "idle", // "idle" | "paused" | "playing" | "ended"
  endedAt: null, // the clip time a `once` stream ended at
  message: null, // {text, error}: the last thing the page had to say
});

/// Seconds rounded to the millisecond, without trailing zeros: `0.708`, `3`.
export function formatSeconds(s) {
  if (!Number.isFinite(s)) return String(s);
  const text = (Math.round(s * 1000) / 1000).toFixed(3).replace(/\.?0+$/, "");
  return text === "-0" ? "0" : text;
}

/// Milliseconds as a person reads them: one decimal under 10 ms, whole above.
export const formatMs = (ms) => `${Math.abs(ms) < 10 ? ms.toFixed(1) : Math.round(ms)} ms`;

/// A byte rate as a person reads it: B/s, kB/s (one decimal under 10) or MB/s.
export function formatBytes(perSecond) {
  const [value, unit] = perSecond < 1000 ? [perSecond, "B/s"] : perSecond < 1e6 ? [perSecond / 1e3, "kB/s"] : [perSecond / 1e6, "MB/s"];
  return `${unit === "B/s" || value >= 10 ? Math.round(value) : value.toFixed(1)} ${unit}`;
}

/// The next status after `action`:
/// `select {clip}`, `deselect` (it was deleted), `adopt {clip}` (a crossfade's clip is now the page's),
/// `graph {name}` (a graph plays on the clip's skeleton; `null`: the clip again),
/// `play`, `pause`, `ended {time}`, `message {text, error}`.
export function reduceStatus(s, action) {
  switch (action.type) {
    case "select":
      return { ...s, clip: action.clip, playing: action.clip.name, mode: "paused", endedAt: null, message: null };
    case "deselect":
      return { ...initialStatus, message: s.message };
    case "adopt":
      return { ...s, clip: action.clip, playing: action.clip.name };
    case "graph":
      return { ...s, playing: action.name ? `graph ${action.name}` : s.clip?.name ?? null };
    case "play":
      // Playing again makes an end, and any words that were not an error, stale.
      return { ...s, mode: "playing", endedAt: null, message: s.message?.error ? s.message : null };
    case "pause":
      return { ...s, mode: s.clip ? "paused" : "idle" };
    case "ended":
      return { ...s, mode: "ended", endedAt: action.time, message: null };
    case "message":
      return { ...s, message: { text: action.text, error: Boolean(action.error) } };
    default:
      throw new Error(`no status action "${action.type}"`);
  }
}

/// The header's words and the status line's, and whether the line is an error.
export function statusView(s) {
  const header = s.playing ? `${s.mode === "idle" ? "" : `${s.mode}: `}${s.playing}` : "";
  if (s.message) return { header, line: s.message.text, error: s.message.error };
  if (s.mode === "ended") return { header, line: `${s.playing} ended at ${formatSeconds(s.endedAt)} s — Play starts it over`, error: false };
  if (!s.clip) return { header, line: "", error: false };
  const { name, joints, start, end } = s.clip;
  return { header, line: `${name}: ${joints} joints, ${formatSeconds(start)}–${formatSeconds(end)} s`, error: false };
}
