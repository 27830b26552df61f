// The labelling page's state, shared by its modules: the page's config, the
// document (the list of objects, each with its own binary mask, plus the
// "no action-object" flag), what the server said about it (meta), whether
// the page may change it (editable), the tool state, the work under way,
// the undo history and the clock.
//
// An object (instance) is {key, kind, label, colour, mask, engine, box,
// strokes, hidden}: `engine` is GrabCut's last answer for it, null while the
// server has no session; `box` the last GrabCut box drawn for it (null: its
// mask's bounding box stands in); `strokes` the GrabCut strokes since that
// box, shown faintly (not saved, not in the undo history); `hidden` hides it
// on the canvas (not saved).

import { ActiveClock } from "./autosave.js";
import { History } from "./history.js";
import { decodeRuns, encodeRuns } from "./mask_codec.js";

export const config = JSON.parse(document.getElementById("label-config").textContent);
export const W = config.frame.width;
export const H = config.frame.height;
export const N = W * H;
export const reviewing = config.mode === "review";
// Whether the person may change the document now: not before it is loaded,
// not while it is done or reviewed (until "Edit"), on the review page only
// while fixing. setEditable() changes it; importers see the new value.
export let editable = false;
export const $ = (selector) => document.querySelector(selector);
export const $$ = (selector) => [...document.querySelectorAll(selector)];

const PALETTE = [
  [0, 180, 255],
  [255, 60, 170],
  [255, 140, 0],
  [255, 214, 0],
  [110, 220, 60],
  [150, 95, 255],
  [0, 205, 170],
  [255, 110, 110],
];

export const doc = { instances: [], noActionObject: false };
export const meta = {
  version: 0, status: "todo", timeSpent: 0, reviewComment: null, reviewer: null, reviewedAt: null,
  fixedBy: null, fixedAt: null, author: null, id: null, historyUrl: null,
};
// What the person has chosen and is doing: read by the view, set by the tools.
export const ui = {
  selectedKey: null,
  tool: reviewing ? "pan" : "box",
  brushRadius: Math.max(3, Math.round(Math.min(W, H) / 80)),
  spaceHeld: false,
  drag: null,
  pointer: null, // last pointer position on the canvas (screen pixels)
  polygon: null, // the polygon being drawn: {points: [{x, y}, ...]} in image coordinates
};
// Server steps under way (GrabCut) and the last one that failed, for the
// save indicator: {what, reason, retry} (null: none, or dismissed).
export const work = { running: 0, dropped: null };
export const lostEngines = new Set(); // keys whose server session no longer matches the page
export const history = new History(100);
export const clock = new ActiveClock();

let lastSnapshot = null; // the state the next history entry starts from

export function setEditable(on) {
  editable = on;
}

export function finished() {
  return meta.status === "done" || meta.status === "reviewed";
}

export function instance(key) {
  return doc.instances.find((i) => i.key === key) || null;
}

export function selected() {
  return instance(ui.selectedKey);
}

export function newKey() {
  return `o${Date.now().toString(36)}${Math.random().toString(36).slice(2, 6)}`;
}

// The first palette colour no object has (the palette again when all are taken).
function freeColour(taken) {
  return PALETTE.find((c) => !taken.includes(c)) || PALETTE[taken.length % PALETTE.length];
}

export function makeInstance(fields = {}, others = doc.instances) {
  return {
    key: newKey(),
    kind: null,
    label: null,
    colour: freeColour(others.map((i) => i.colour)),
    mask: new Uint8Array(N),
    engine: null,
    box: null,
    strokes: [],
    hidden: false,
    ...fields,
  };
}

// Replace the document with the objects loaded from the server.
export function loadDocument(instances, noActionObject) {
  const list = [];
  for (const fields of instances) list.push(makeInstance(fields, list));
  doc.instances = list;
  doc.noActionObject = noActionObject;
  if (!instance(ui.selectedKey)) ui.selectedKey = doc.instances[0]?.key ?? null;
  lostEngines.clear();
  lastSnapshot = snapshot();
}

export function snapshot() {
  return {
    selectedKey: ui.selectedKey,
    noActionObject: doc.noActionObject,
    instances: doc.instances.map((i) => ({
      key: i.key,
      kind: i.kind,
      label: i.label,
      colour: i.colour,
      mask: encodeRuns(i.mask),
      engine: i.engine ? encodeRuns(i.engine) : null,
      box: i.box,
    })),
  };
}

export function restore(snap) {
  const hidden = new Set(doc.instances.filter((i) => i.hidden).map((i) => i.key));
  doc.noActionObject = snap.noActionObject;
  doc.instances = snap.instances.map((i) => ({
    ...i,
    box: i.box ?? null,
    hidden: hidden.has(i.key),
    mask: decodeRuns(i.mask, N),
    engine: i.engine && !lostEngines.has(i.key) ? decodeRuns(i.engine, N) : null,
  }));
  ui.selectedKey = instance(snap.selectedKey) ? snap.selectedKey : doc.instances[0]?.key ?? null;
  lastSnapshot = snap;
}

// Record the state now in the undo history, as the result of `op` (a GrabCut
// step, or null for an edit made on the page alone).
export function record(op = null) {
  const after = snapshot();
  history.push({ before: lastSnapshot, after, op });
  lastSnapshot = after;
}

// Record a replacement of the whole document (loading the saved version):
// undoing it brings `before` back.
export function recordReplaced(before) {
  history.push({ before, after: lastSnapshot, op: null });
}

// The history read back from the server, in place of this page's: it ends
// where the loaded document is when `current`; otherwise one more step goes
// from where it ended to the loaded document (undo it to go back there).
export function adoptHistory(stored, { current }) {
  history.replaceWith(stored);
  const end = history.latest;
  if (!current && end) history.push({ before: end, after: lastSnapshot, op: null });
}

// The object edits go to: the selected one, or a new one (`fresh`: also
// when the selected one already has a mask, as a new box does).
export function target({ fresh = false } = {}) {
  let inst = selected();
  if (!inst || (fresh && inst.mask.includes(1))) {
    inst = makeInstance();
    doc.instances.push(inst);
    ui.selectedKey = inst.key;
  }
  if (doc.noActionObject) {
    doc.noActionObject = false;
    $("#no-ao").checked = false;
  }
  inst.hidden = false; // nobody edits what they cannot see
  return inst;
}
