// The playback settings as the page's controls hold them, and the mapping
// of clip time back to request time (for the seek bar and the plots).

import { $ } from "./dom.js";
import { EASES, unease } from "./math.js";
import { state } from "./state.js";

/// The stream and pose options the controls choose: space, ease, and playback if not the clip's.
export function options() {
  const o = { space: $("space").value, ease: $("ease").value };
  if ($("playback").value) o.playback = $("playback").value;
  return o;
}

/// The frame rate asked for (30 when the box holds none).
export const fps = () => Math.round(Number($("fps").value)) || 30;

/// The playback mode in force: the page's choice, else the clip's default.
export const playbackMode = () => $("playback").value || state.clip?.playback || "loop";

/// The request time in the clip's range whose eased clip time is `clipTime`.
export function requestTimeOf(clipTime) {
  const { start, end } = state.clip || { start: 0, end: 0 };
  const ease = EASES[$("ease").value];
  if (end <= start || ease === EASES.linear) return clipTime;
  const y = Math.min(1, Math.max(0, (clipTime - start) / (end - start)));
  return start + unease(ease, y) * (end - start);
}
