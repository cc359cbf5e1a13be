// The page's elements: lookup, creation, the status line, and the canvas
// helpers both views use.

import { state } from "./state.js";
import { reduceStatus, statusView } from "./status.js";

export const $ = (id) => document.getElementById(id);

/// The plot colours: x, y, z, w, then more parameter components (the ground's axes use the first three).
export const COLORS = ["#ff5c5c", "#5cd65c", "#5c9dff", "#c8c8c8", "#e0a040", "#c070e0"];

/// An element with properties and children.
export function el(tag, props = {}, ...children) {
  const e = Object.assign(document.createElement(tag), props);
  e.append(...children);
  return e;
}

export const row = (...children) => el("div", { className: "row" }, ...children);

/// Tells the status (status.js) what happened, and shows what it now says
/// in the header and the status line.
export function dispatchStatus(action) {
  state.status = reduceStatus(state.status, action);
  const view = statusView(state.status);
  $("status").textContent = view.line;
  $("status").classList.toggle("error", view.error);
  $("now-playing").textContent = view.header;
}

/// A message on the status line (until the next one, or until playing makes it stale).
export function setStatus(text, isError = false) {
  dispatchStatus({ type: "message", text, error: isError });
}

/// Sizes a canvas's pixels to its box (the layout gives it the height the
/// controls leave, so the page fits one screen). Returns the pixel ratio.
export function sizeCanvas(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
  const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
  return dpr;
}

/// One stroked path: `build` adds its segments.
export function stroke(ctx, color, width, build) {
  ctx.beginPath();
  build();
  ctx.strokeStyle = color;
  ctx.lineWidth = width;
  ctx.stroke();
}
