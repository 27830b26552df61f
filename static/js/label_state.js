// The labelling page's state, shared by its modules: the page's config, the
// document (the list of objects, each with its own binary mask, plus the
// "no action-object" flag), what the server said about it (meta), the tool
// state, the undo history and the clock.
//
// An object (instance) is {key, kind, label, colour, mask, engine}: `engine`
// is GrabCut's last answer for it, null while the server has no session.

import { ActiveClock } from "./autosave.js";
import { History } from "./history.js";
import { decodeRuns, encodeRuns } from "./mask_codec.js";

export const config = JSON.parse(document.getElementById("label-config").textContent);
export const W = config.frame.width;
export const H = config.frame.height;
export const N = W * H;
export const editable = config.mode === "label";
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
export const meta = { version: 0, status: "todo", timeSpent: 0, reviewComment: null, reviewer: null, author: null, id: null };
// What the person has chosen and is doing: read by the view, set by the tools.
export const ui = {
  selectedKey: null,
  tool: editable ? "box" : "pan",
  brushRadius: Math.max(3, Math.round(Math.min(W, H) / 80)),
  spaceHeld: false,
  drag: null,
  pointer: null, // last pointer position on the canvas (screen pixels)
};
export const lostEngines = new Set(); // keys whose server session no longer matches the page
export const history = new History(100);
export const clock = new ActiveClock();

let colourCounter = 0;
let lastSnapshot = null; // the state the next history entry starts from

export function instance(key) {
  return doc.instances.find((i) => i.key === key) || null;
}

export function selected() {
  return instance(ui.selectedKey);
}

export function newKey() {
  return `o${Date.now().toString(36)}${Math.random().toString(36).slice(2, 6)}`;
}

export function makeInstance(fields = {}) {
  return {
    key: newKey(),
    kind: null,
    label: null,
    colour: PALETTE[colourCounter++ % PALETTE.length],
    mask: new Uint8Array(N),
    engine: null,
    ...fields,
  };
}

// Replace the document with the objects loaded from the server.
export function loadDocument(instances, noActionObject) {
  colourCounter = 0;
  doc.instances = instances.map((fields) => makeInstance(fields));
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
    })),
  };
}

export function restore(snap) {
  doc.noActionObject = snap.noActionObject;
  doc.instances = snap.instances.map((i) => ({
    ...i,
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

// The object edits go to: the selected one, or a new one.
export function target() {
  let inst = selected();
  if (!inst) {
    inst = makeInstance();
    doc.instances.push(inst);
    ui.selectedKey = inst.key;
  }
  if (doc.noActionObject) {
    doc.noActionObject = false;
    $("#no-ao").checked = false;
  }
  return inst;
}
