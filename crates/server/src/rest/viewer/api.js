// The server's REST API as the page calls it: the token (kept in this tab),
// problem documents as one line, and the WebSocket subprotocols that carry
// the token.

import { $ } from "./dom.js";

const TOKEN_KEY = "inbetween.token";

/// The token this tab uses, if any.
export const savedToken = () => sessionStorage.getItem(TOKEN_KEY);

/// Keeps `token` for this tab (an empty one forgets it).
export function saveToken(token) {
  if (token) sessionStorage.setItem(TOKEN_KEY, token);
  else sessionStorage.removeItem(TOKEN_KEY);
}

export function authHeaders() {
  const token = savedToken();
  return token ? { Authorization: `Bearer ${token}` } : {};
}

/// A problem document (docs/api.md) as one line: its detail, then its code
/// and where (`pointer` or `parameter`). Never "[object Object]".
export function describeProblem(p, status) {
  if (typeof p === "string") return p;
  if (!p || typeof p !== "object") return `HTTP ${status ?? "error"}`;
  const what = p.detail || p.title || JSON.stringify(p);
  const where = p.pointer || p.parameter;
  const code = [p.code, status ?? p.status].filter((x) => x != null).join(", ");
  return `${what}${code ? ` (${code}${where ? ` at ${where}` : ""})` : ""}`;
}

export async function problemText(response) {
  const text = await response.text().catch(() => "");
  try {
    return describeProblem(JSON.parse(text), response.status);
  } catch {
    return `HTTP ${response.status}${text ? `: ${text.slice(0, 200)}` : ""}`;
  }
}

/// `fetch`, with the request named when the network fails.
export async function request(path, options) {
  try {
    return await fetch(path, options);
  } catch (e) {
    throw new Error(`${options.method || "GET"} ${path}: ${e.message}`);
  }
}

/// How often a request refused for now (429, 503 with `Retry-After`) is
/// asked again, and the longest wait the page accepts before each.
const RETRIES = 3;
const LONGEST_RETRY_S = 5;

/// A JSON answer, the token sent; a refusal throws its problem as one line.
/// The page's reads come in bursts (a clip's pose, curves, framing and
/// thumbnails at once) that can pass the caller's work share for a moment
/// (docs/api.md, "Work and its price"): such a refusal is waited out.
export async function api(path, options = {}, retries = RETRIES) {
  const headers = { ...authHeaders(), ...(options.headers || {}) };
  const response = await request(path, { ...options, headers });
  const after = response.headers.get("retry-after");
  const wait = after === null ? NaN : Number(after);
  if ((response.status === 429 || response.status === 503) && retries > 0 && wait >= 0 && wait <= LONGEST_RETRY_S) {
    await new Promise((resolve) => setTimeout(resolve, Math.max(wait, 0.1) * 1000));
    return api(path, options, retries - 1);
  }
  if (response.status === 401) wantToken();
  if (!response.ok) throw new Error(await problemText(response));
  return response.status === 204 ? null : response.json();
}

/// Points at the token field: the server wants a (different) token.
export function wantToken() {
  $("token-form").classList.add("wanted");
  $("token").focus();
}

/// Every item of a listing route (`/v1/clips`, `/v1/characters`, …), page
/// by page: `key` names the page's array.
export async function listAll(path, key) {
  const items = [];
  let cursor = null;
  for (let page = 0; page < 20; page++) {
    const q = cursor ? `&cursor=${encodeURIComponent(cursor)}` : "";
    const body = await api(`${path}?limit=500${q}`);
    items.push(...body[key]);
    cursor = body.next_cursor;
    if (!cursor) break;
  }
  return items;
}

export const postJson = (path, body) =>
  api(path, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });

/// The subprotocols that carry the token: a browser cannot set headers on
/// a WebSocket, so it offers `inbetween.bearer.<base64url of the token>`
/// next to `inbetween`, which the server selects (README, Security).
export function streamProtocols() {
  const token = savedToken();
  if (!token) return [];
  const bytes = new TextEncoder().encode(token);
  const b64 = btoa(String.fromCharCode(...bytes)).replace(/\+/g, "-").replace(/\//g, "_").replace(/=+$/, "");
  return ["inbetween", `inbetween.bearer.${b64}`];
}

/// A WebSocket URL on this server.
export function socketUrl(path) {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  return `${scheme}://${location.host}${path}`;
}
