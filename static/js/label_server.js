// The labelling page's calls to the server, all through api.js: the
// annotation (read, save, time, review), its masks, the GrabCut steps,
// whose answers are masks sent as PNG, and a model's proposals.

import { api, request } from "./api.js";
import { H, N, W, config } from "./label_state.js";
import { maskFromRGBA } from "./mask_codec.js";

async function decodeMaskPng(blob) {
  let bitmap;
  try {
    bitmap = await createImageBitmap(blob, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
  } catch {
    throw new Error("the server's mask could not be read as an image");
  }
  if (bitmap.width !== W || bitmap.height !== H) throw new Error(`mask is ${bitmap.width}x${bitmap.height}, the frame ${W}x${H}`);
  const c = document.createElement("canvas");
  c.width = W;
  c.height = H;
  const g = c.getContext("2d", { willReadFrequently: true });
  g.drawImage(bitmap, 0, 0);
  bitmap.close();
  return maskFromRGBA(g.getImageData(0, 0, W, H).data, N);
}

export async function fetchMask(url) {
  const response = await request("GET", url, undefined, { cache: "no-cache", headers: { Accept: "image/png" } });
  return decodeMaskPng(await response.blob());
}

// GrabCut's current mask for an object (its server session's last answer).
export function fetchEngineMask(key) {
  return fetchMask(`${config.urls.grabcut.mask}?frame_id=${config.frame.id}&instance=${encodeURIComponent(key)}`);
}

// Carry the user's annotation: url is a frame's propagate URL (body
// {direction, count, replace, version}) or this frame's copy_previous URL
// (body {replace, version}) -> the carried annotation.
export function carry(url, body) {
  return api("POST", url, body);
}

// A window of the sequence's frames: {start} (a position), {at} (a frame's number), {count}.
export function getFilmstrip(params = {}) {
  const query = new URLSearchParams(Object.entries(params).filter(([, v]) => v !== undefined && v !== null));
  return api("GET", `${config.urls.filmstrip}?${query}`);
}

// kind: "box", "stroke" or "undo"; the answer is the object's new mask.
export async function grabcut(kind, body) {
  const response = await request("POST", config.urls.grabcut[kind], { frame_id: config.frame.id, ...body }, { headers: { Accept: "image/png" } });
  return decodeMaskPng(await response.blob());
}

export function getAnnotation() {
  return api("GET", config.urls.annotation);
}

export function putAnnotation(body, { keepalive = false } = {}) {
  return api("PUT", config.urls.annotation, body, { keepalive });
}

// A reviewer's fix of the annotation under review (the review page's own URL).
export function putFix(body, { keepalive = false } = {}) {
  return api("PUT", config.urls.fix, body, { keepalive });
}

export function postReopen(body) {
  return api("POST", config.urls.reopen, body);
}

// {open: true} every heartbeat while the page shows the frame, {open: false} on leaving -> {others}.
export function postPresence(open, { keepalive = false } = {}) {
  return api("POST", config.urls.presence, { open }, { keepalive });
}

// The stored undo history: {version, blob}, or null when there is none.
export async function getHistory(url) {
  try {
    const response = await request("GET", url, undefined, { headers: { Accept: "application/gzip" } });
    return { version: Number(response.headers.get("X-Annotation-Version")), blob: await response.blob() };
  } catch (err) {
    if (err.status === 404) return null;
    throw err;
  }
}

export function putHistory(url, version, blob, { keepalive = false } = {}) {
  return request("PUT", `${url}?version=${version}`, blob, { headers: { "Content-Type": "application/gzip" }, keepalive });
}

export function postTime(seconds) {
  return api("POST", config.urls.time, { seconds }, { keepalive: true });
}

export function postReview(body) {
  return api("POST", config.urls.review, body);
}

// A trained run's proposals for this frame: {annotation, suggestion} (200), or {queued, message} (202).
export function postSuggest(body) {
  return api("POST", config.urls.suggest, body);
}

export function postAcceptProposal(body) {
  return api("POST", config.urls.accept_proposal, body);
}
