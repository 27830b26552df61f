// The labelling page (and, read-only, the review page): a canvas with zoom
// and pan, GrabCut box and fg/bg strokes run on the server, manual paint and
// erase, several objects per frame, undo/redo, autosave with a version check.
//
// The document is the list of objects (instances), each with its own binary
// mask, plus the "no action-object" flag. Every edit is recorded in the undo
// history as before/after snapshots (row runs). GrabCut results are merged
// into an object's mask by what the engine changed since its previous result,
// so manual paint and erase survive later strokes; undoing or redoing a
// GrabCut step also steps the server's session, so the two stay in step.

import { api, ApiError, request } from "./api.js";
import { ActiveClock, Autosaver, retried, saveText } from "./autosave.js";
import { dragBox, fit, pan, toImage, toPixel, toScreen, wheelFactor, zoomAt } from "./geometry.js";
import { History } from "./history.js";
import { decodeRuns, encodeCocoRle, encodeRuns, maskFromRGBA } from "./mask_codec.js";
import { countSet, paintPolyline, paintSegment } from "./raster.js";

const config = JSON.parse(document.getElementById("label-config").textContent);
const W = config.frame.width;
const H = config.frame.height;
const N = W * H;
const editable = config.mode === "label";
const $ = (selector) => document.querySelector(selector);
const $$ = (selector) => [...document.querySelectorAll(selector)];

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
const TOOLS = { box: "b", fg: "f", bg: "g", paint: "p", erase: "e", pan: "h" };

// ---------------------------------------------------------------- state

const doc = { instances: [], noActionObject: false }; // instance: {key, kind, label, colour, mask, engine}
const meta = { version: 0, status: "todo", timeSpent: 0, reviewComment: null, reviewer: null, author: null, id: null };
let selectedKey = null;
let pendingStatus = null;
let colourCounter = 0;
let lastSnapshot = null;
const lostEngines = new Set(); // keys whose server session no longer matches the page
const history = new History(100);
const clock = new ActiveClock();
let keepalive = false;

let tool = editable ? "box" : "pan";
let brushRadius = Math.max(3, Math.round(Math.min(W, H) / 80));
let opacity = 0.5;
let showMask = true;
let view = { scale: 1, tx: 0, ty: 0 };
let fitted = false;
let spaceHeld = false;
let drag = null;
let pointer = null; // last pointer position on the canvas (screen pixels)
let currentView = "rgb";
let busy = 0;

// Serialise GrabCut calls, undo and redo: the server sees them in page order.
let queue = Promise.resolve();
function enqueue(task) {
  queue = queue.then(task).catch((err) => showMessage(errorText(err), "error"));
  return queue;
}

// ---------------------------------------------------------------- canvases

const canvas = $("#canvas");
const stage = $("#stage");
const ctx = canvas.getContext("2d");
const fillCanvas = document.createElement("canvas");
const edgeCanvas = document.createElement("canvas");
fillCanvas.width = edgeCanvas.width = W;
fillCanvas.height = edgeCanvas.height = H;
const fillCtx = fillCanvas.getContext("2d");
const edgeCtx = edgeCanvas.getContext("2d");
const fillData = fillCtx.createImageData(W, H);
const edgeData = edgeCtx.createImageData(W, H);

const images = {};
function baseImage(name) {
  if (!images[name]) {
    const img = new Image();
    img.onload = draw;
    img.src = config.frame[`${name}_url`];
    images[name] = img;
  }
  return images[name];
}

// Recolour the overlay inside rect (image pixels): every object in its
// colour (the selected one on top and stronger), the selected one's outline.
function renderOverlay(rect = { x0: 0, y0: 0, x1: W, y1: H }) {
  const x0 = Math.max(0, rect.x0 - 1);
  const y0 = Math.max(0, rect.y0 - 1);
  const x1 = Math.min(W, rect.x1 + 1);
  const y1 = Math.min(H, rect.y1 + 1);
  if (x0 >= x1 || y0 >= y1) return;
  const f = fillData.data;
  const e = edgeData.data;
  const list = doc.instances;
  const sel = list.findIndex((i) => i.key === selectedKey);
  const selMask = sel >= 0 ? list[sel].mask : null;
  for (let y = y0; y < y1; y++) {
    for (let x = x0; x < x1; x++) {
      const i = y * W + x;
      const p = 4 * i;
      let owner = -1;
      if (selMask && selMask[i]) owner = sel;
      else for (let k = list.length - 1; k >= 0; k--) if (list[k].mask[i]) { owner = k; break; }
      if (owner < 0) {
        f[p + 3] = 0;
      } else {
        const c = list[owner].colour;
        f[p] = c[0];
        f[p + 1] = c[1];
        f[p + 2] = c[2];
        f[p + 3] = owner === sel ? 255 : 150;
      }
      const edge =
        owner === sel && selMask &&
        (x === 0 || !selMask[i - 1] || x === W - 1 || !selMask[i + 1] || y === 0 || !selMask[i - W] || y === H - 1 || !selMask[i + W]);
      if (edge) {
        e[p] = e[p + 1] = e[p + 2] = 255;
        e[p + 3] = 235;
      } else {
        e[p + 3] = 0;
      }
    }
  }
  fillCtx.putImageData(fillData, 0, 0, x0, y0, x1 - x0, y1 - y0);
  edgeCtx.putImageData(edgeData, 0, 0, x0, y0, x1 - x0, y1 - y0);
  draw();
}

let frameRequested = false;
function draw() {
  if (frameRequested) return;
  frameRequested = true;
  requestAnimationFrame(paint);
}

function paint() {
  frameRequested = false;
  const dpr = window.devicePixelRatio || 1;
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = "#14171d";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.setTransform(dpr * view.scale, 0, 0, dpr * view.scale, dpr * view.tx, dpr * view.ty);
  ctx.imageSmoothingEnabled = view.scale < 2;
  const base = baseImage(currentView);
  if (base.complete && base.naturalWidth) ctx.drawImage(base, 0, 0, W, H);
  else {
    ctx.fillStyle = "#252a33";
    ctx.fillRect(0, 0, W, H);
  }
  if (showMask) {
    ctx.globalAlpha = opacity;
    ctx.drawImage(fillCanvas, 0, 0);
    ctx.globalAlpha = 1;
    ctx.drawImage(edgeCanvas, 0, 0);
  }
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  const corner = toScreen(view, 0, 0);
  ctx.strokeStyle = "rgba(255,255,255,0.25)";
  ctx.lineWidth = 1;
  ctx.strokeRect(corner.x - 0.5, corner.y - 0.5, W * view.scale + 1, H * view.scale + 1);
  paintPreview();
}

// What is being drawn right now, and the brush outline, in screen pixels.
function paintPreview() {
  if (drag?.type === "box") {
    const a = toScreen(view, drag.start.x, drag.start.y);
    const b = toScreen(view, drag.end.x, drag.end.y);
    ctx.setLineDash([6, 4]);
    ctx.strokeStyle = "#ffe14d";
    ctx.lineWidth = 2;
    ctx.strokeRect(Math.min(a.x, b.x), Math.min(a.y, b.y), Math.abs(b.x - a.x), Math.abs(b.y - a.y));
    ctx.setLineDash([]);
  }
  if (drag?.type === "stroke") {
    ctx.strokeStyle = drag.label === "fg" ? "rgba(60, 220, 90, 0.6)" : "rgba(255, 70, 70, 0.6)";
    ctx.fillStyle = ctx.strokeStyle;
    ctx.lineWidth = Math.max(1, 2 * brushRadius * view.scale);
    ctx.lineCap = ctx.lineJoin = "round";
    ctx.beginPath();
    drag.points.forEach((p, i) => {
      const s = toScreen(view, p.x + 0.5, p.y + 0.5);
      if (i === 0) ctx.moveTo(s.x, s.y);
      else ctx.lineTo(s.x, s.y);
    });
    if (drag.points.length === 1) {
      const s = toScreen(view, drag.points[0].x + 0.5, drag.points[0].y + 0.5);
      ctx.arc(s.x, s.y, brushRadius * view.scale, 0, 2 * Math.PI);
      ctx.fill();
    } else ctx.stroke();
  }
  if (pointer && editable && ["fg", "bg", "paint", "erase"].includes(tool) && !spaceHeld) {
    ctx.strokeStyle = { fg: "#3cdc5a", bg: "#ff4646", paint: "#ffffff", erase: "#ffffff" }[tool];
    ctx.lineWidth = 1.5;
    ctx.setLineDash(tool === "erase" ? [3, 3] : []);
    ctx.beginPath();
    ctx.arc(pointer.x, pointer.y, Math.max(2, brushRadius * view.scale), 0, 2 * Math.PI);
    ctx.stroke();
    ctx.setLineDash([]);
  }
}

function resize() {
  const dpr = window.devicePixelRatio || 1;
  const { clientWidth, clientHeight } = stage;
  canvas.width = Math.max(1, Math.round(clientWidth * dpr));
  canvas.height = Math.max(1, Math.round(clientHeight * dpr));
  canvas.style.width = `${clientWidth}px`;
  canvas.style.height = `${clientHeight}px`;
  if (!fitted && clientWidth > 0) {
    fitView();
    fitted = true;
  }
  draw();
}

function fitView() {
  view = fit(stage.clientWidth, stage.clientHeight, W, H);
  updateZoomLabel();
  draw();
}

function setView(next) {
  view = next;
  updateZoomLabel();
  draw();
}

function updateZoomLabel() {
  $("#zoom-value").textContent = `${Math.round(view.scale * 100)}%`;
}

// ---------------------------------------------------------------- document

function instance(key) {
  return doc.instances.find((i) => i.key === key) || null;
}

function selected() {
  return instance(selectedKey);
}

function newKey() {
  return `o${Date.now().toString(36)}${Math.random().toString(36).slice(2, 6)}`;
}

function makeInstance(fields = {}) {
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

function snapshot() {
  return {
    selectedKey,
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

function restore(snap) {
  doc.noActionObject = snap.noActionObject;
  doc.instances = snap.instances.map((i) => ({
    ...i,
    mask: decodeRuns(i.mask, N),
    engine: i.engine && !lostEngines.has(i.key) ? decodeRuns(i.engine, N) : null,
  }));
  selectedKey = instance(snap.selectedKey) ? snap.selectedKey : doc.instances[0]?.key ?? null;
  lastSnapshot = snap;
}

// Record the edit just made (undoable) and let autosave send it.
function commit(op = null) {
  const after = snapshot();
  history.push({ before: lastSnapshot, after, op });
  lastSnapshot = after;
  edited();
}

function edited() {
  renderOverlay();
  renderInstances();
  updateControls();
  autosaver.changed();
}

// The object edits go to: the selected one, or a new one.
function target() {
  let inst = selected();
  if (!inst) {
    inst = makeInstance();
    doc.instances.push(inst);
    selectedKey = inst.key;
  }
  if (doc.noActionObject) {
    doc.noActionObject = false;
    $("#no-ao").checked = false;
  }
  return inst;
}

function addInstance() {
  const inst = makeInstance();
  doc.instances.push(inst);
  selectedKey = inst.key;
  doc.noActionObject = false;
  commit();
  setTool("box");
}

function deleteInstance(key) {
  const i = doc.instances.findIndex((x) => x.key === key);
  if (i < 0) return;
  doc.instances.splice(i, 1);
  if (selectedKey === key) selectedKey = doc.instances[Math.min(i, doc.instances.length - 1)]?.key ?? null;
  commit();
}

function select(key) {
  if (!instance(key)) return;
  selectedKey = key;
  renderOverlay();
  renderInstances();
}

// ---------------------------------------------------------------- GrabCut

async function decodeMaskPng(blob) {
  const bitmap = await createImageBitmap(blob, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
  if (bitmap.width !== W || bitmap.height !== H) throw new Error(`mask is ${bitmap.width}x${bitmap.height}, the frame ${W}x${H}`);
  const c = document.createElement("canvas");
  c.width = W;
  c.height = H;
  const g = c.getContext("2d", { willReadFrequently: true });
  g.drawImage(bitmap, 0, 0);
  bitmap.close();
  return maskFromRGBA(g.getImageData(0, 0, W, H).data, N);
}

async function fetchMask(url) {
  const response = await request("GET", url, undefined, { cache: "no-cache", headers: { Accept: "image/png" } });
  return decodeMaskPng(await response.blob());
}

async function grabcutCall(kind, body) {
  const response = await request("POST", config.urls.grabcut[kind], { frame_id: config.frame.id, ...body }, { headers: { Accept: "image/png" } });
  return decodeMaskPng(await response.blob());
}

// Box: the object starts again from the engine's mask. Stroke: the pixels
// the engine changed since its last answer take its new value, and the
// stroke itself is painted, so earlier manual edits elsewhere stay.
function runGrabcut(kind, params) {
  const key = target().key;
  return enqueue(async () => {
    setBusy(+1);
    try {
      const mask = await grabcutCall(kind, { instance: key, ...params });
      const inst = instance(key);
      if (!inst) return;
      if (kind === "box" || !inst.engine) {
        inst.mask = mask.slice();
      } else {
        for (let i = 0; i < N; i++) if (mask[i] !== inst.engine[i]) inst.mask[i] = mask[i];
        const points = params.points.map(([x, y]) => ({ x, y }));
        paintPolyline(inst.mask, W, H, points, params.radius, params.label === "fg" ? 1 : 0);
      }
      inst.engine = mask;
      if (kind === "box") lostEngines.delete(key);
      commit({ kind, key, params });
      if (kind === "box" && !mask.includes(1)) {
        showMessage("GrabCut found no object in this box: draw it around the whole object, or mark the object with the Object brush (F).", "info");
      }
    } catch (err) {
      showMessage(`GrabCut did not run: ${errorText(err)}`, "error");
    } finally {
      setBusy(-1);
      renderInstances(); // also when it failed: a new object may have been made for it
    }
  });
}

// Keep the server's session in step when a GrabCut step is undone or redone;
// if it cannot follow, GrabCut starts afresh with the next box.
async function replayOnServer(op, undoing) {
  if (lostEngines.has(op.key)) return;
  try {
    if (undoing) await grabcutCall("undo", { instance: op.key });
    else await grabcutCall(op.kind, { instance: op.key, ...op.params });
  } catch {
    lostEngines.add(op.key);
    const inst = instance(op.key);
    if (inst) inst.engine = null;
  }
}

function undo() {
  if (!editable) return;
  enqueue(async () => {
    const entry = history.undo();
    if (!entry) return;
    restore(entry.before);
    if (entry.op) await replayOnServer(entry.op, true);
    edited();
  });
}

function redo() {
  if (!editable) return;
  enqueue(async () => {
    const entry = history.redo();
    if (!entry) return;
    restore(entry.after);
    if (entry.op) await replayOnServer(entry.op, false);
    edited();
  });
}

// ---------------------------------------------------------------- saving

function saveBody() {
  return {
    version: meta.version,
    instances: doc.instances.map((i) => ({ key: i.key, kind: i.kind, label: i.label, mask: encodeCocoRle(i.mask, W, H) })),
    no_action_object: doc.noActionObject,
    status: pendingStatus,
  };
}

async function save() {
  const body = saveBody();
  const seconds = clock.take();
  body.time_spent_delta_s = Math.round(Math.min(seconds, 3600) * 1000) / 1000;
  try {
    const data = await api("PUT", config.urls.annotation, body, { keepalive });
    if (pendingStatus === body.status) pendingStatus = null;
    applyMeta(data);
  } catch (err) {
    clock.giveBack(seconds);
    if (err.status === 409) {
      showConflict(err.body.current_version);
    } else if (err.status === 400 && err.body.error !== "csrf" && body.status) {
      // The status could not be set (nothing drawn, an empty object): say why, save the rest.
      pendingStatus = null;
      showMessage(err.message, "error");
      return save();
    } else if (!retried(err.status)) {
      showMessage(errorText(err), "error"); // refused: the whole reason, fields too
    }
    throw err;
  }
}

const autosaver = new Autosaver({ save, delay: 500, maxWait: 1500, onState: showSaveState });

function showSaveState() {
  const el = $("#save-state");
  if (!el) return;
  el.dataset.state = autosaver.state;
  el.textContent = saveText(autosaver);
}

function applyMeta(data) {
  meta.version = data.version;
  meta.status = data.status;
  meta.timeSpent = data.time_spent_s;
  meta.reviewComment = data.review_comment;
  meta.reviewer = data.reviewer;
  meta.author = data.author;
  meta.id = data.id;
  updateControls();
}

async function loadAnnotation() {
  const data = await api("GET", config.urls.annotation);
  const masks = await Promise.all(data.instances.map((i) => fetchMask(i.mask_url)));
  const engines = {};
  await Promise.all(
    (data.grabcut || []).map(async (key) => {
      try {
        engines[key] = await fetchMask(`${config.urls.grabcut.mask}?frame_id=${config.frame.id}&instance=${encodeURIComponent(key)}`);
      } catch {
        engines[key] = null;
      }
    }),
  );
  colourCounter = 0;
  doc.instances = data.instances.map((i, k) =>
    makeInstance({ key: i.key || newKey(), kind: i.kind, label: i.label, mask: masks[k], engine: engines[i.key] ?? null }),
  );
  doc.noActionObject = data.no_action_object;
  if (!instance(selectedKey)) selectedKey = doc.instances[0]?.key ?? null;
  lostEngines.clear();
  applyMeta(data);
  lastSnapshot = snapshot();
}

// ---------------------------------------------------------------- conflict banner

function showConflict(current) {
  $("#conflict-version").textContent = current;
  $("#conflict").hidden = false;
}

async function reloadTheirs() {
  await enqueue(async () => {
    const before = snapshot();
    await loadAnnotation();
    history.push({ before, after: lastSnapshot, op: null });
    autosaver.reset();
    $("#conflict").hidden = true;
    renderOverlay();
    renderInstances();
    updateControls();
    showMessage("Loaded the saved version. Undo (Ctrl+Z) brings your version back.", "info");
  });
}

async function keepMine() {
  let data;
  try {
    data = await api("GET", config.urls.annotation);
  } catch (err) {
    showMessage(`Could not read the saved version: ${errorText(err)}`, "error");
    return;
  }
  meta.version = data.version;
  $("#conflict").hidden = true;
  autosaver.resume();
  await autosaver.flush();
}

// ---------------------------------------------------------------- controls

function setTool(name) {
  if (!editable && name !== "pan") return;
  tool = name;
  $$("[data-tool]").forEach((b) => b.classList.toggle("active", b.dataset.tool === tool));
  canvas.dataset.tool = tool;
  $("#tool-hint").textContent = {
    box: "Drag a box around the object: GrabCut outlines it.",
    fg: "Paint over parts that belong to the object (GrabCut).",
    bg: "Paint over background that was taken in (GrabCut).",
    paint: "Paint the mask by hand.",
    erase: "Erase the mask by hand.",
    pan: "Drag to move the image.",
  }[tool];
  draw();
}

function setBrush(radius) {
  brushRadius = Math.min(200, Math.max(1, Math.round(radius)));
  const input = $("#brush-size");
  if (input) input.value = brushRadius;
  const value = $("#brush-size-value");
  if (value) value.textContent = `${brushRadius}px`;
  draw();
}

function setBaseView(name) {
  if (!config.frame[`${name}_url`]) return;
  currentView = name;
  $$("[data-view]").forEach((b) => b.classList.toggle("active", b.dataset.view === name));
  baseImage(name);
  draw();
}

function cycleView() {
  const names = ["rgb", "depth", "dhg"].filter((n) => config.frame[`${n}_url`]);
  setBaseView(names[(names.indexOf(currentView) + 1) % names.length]);
}

function setShowMask(on) {
  showMask = on;
  $("#show-mask").checked = on;
  draw();
}

function setBusy(delta) {
  busy += delta;
  $("#busy").hidden = busy <= 0;
}

function renderInstances() {
  const list = $("#instances");
  list.replaceChildren();
  doc.instances.forEach((inst, k) => {
    const li = document.createElement("li");
    li.className = "instance" + (inst.key === selectedKey ? " selected" : "");
    li.dataset.key = inst.key;
    const area = countSet(inst.mask);
    const [r, g, b] = inst.colour;
    li.innerHTML = `
      <button type="button" class="pick" title="Select (${k + 1})">
        <span class="swatch"></span>
        <span class="name">Object ${k + 1}</span>
        <span class="area">${area ? `${((100 * area) / N).toFixed(1)}%` : "empty"}</span>
      </button>
      <div class="instance-fields">
        <select class="kind" aria-label="kind" ${editable ? "" : "disabled"}>
          <option value="">kind…</option><option value="tactile">tactile</option><option value="visual">visual</option>
        </select>
        <input class="label" placeholder="name (optional)" maxlength="120" aria-label="name" ${editable ? "" : "disabled"}>
        ${editable ? '<button type="button" class="delete" title="Delete object (Del)" aria-label="delete">✕</button>' : ""}
      </div>`;
    li.querySelector(".swatch").style.background = `rgb(${r}, ${g}, ${b})`; // a style attribute would break the CSP
    li.querySelector(".kind").value = inst.kind || "";
    li.querySelector(".label").value = inst.label || "";
    li.querySelector(".pick").addEventListener("click", () => select(inst.key));
    li.querySelector(".kind").addEventListener("change", (e) => {
      inst.kind = e.target.value || null;
      commit();
    });
    li.querySelector(".label").addEventListener("change", (e) => {
      inst.label = e.target.value.trim() || null;
      commit();
    });
    li.querySelector(".delete")?.addEventListener("click", () => deleteInstance(inst.key));
    list.append(li);
  });
  $("#instances-empty").hidden = doc.instances.length > 0;
}

function updateControls() {
  const badge = $("#status-badge");
  badge.className = `status status-${meta.status}`;
  badge.textContent = meta.status.replace("_", " ");
  $("#no-ao").checked = doc.noActionObject;
  const finished = meta.status === "done" || meta.status === "reviewed";
  if (editable) {
    $("#undo").disabled = !history.canUndo;
    $("#redo").disabled = !history.canRedo;
    $("#mark-done").hidden = finished;
    $("#done-next").hidden = finished;
    $("#reopen").hidden = !finished;
  }
  const banner = $("#review-note");
  if (meta.reviewComment) {
    banner.hidden = false;
    banner.classList.toggle("rejected", meta.status === "rejected");
    const who = meta.reviewer ? ` by ${meta.reviewer}` : "";
    $("#review-note-title").textContent = meta.status === "rejected" ? `Returned${who} — please fix:` : `Reviewer's note${who}:`;
    $("#review-note-text").textContent = meta.reviewComment;
  } else {
    banner.hidden = true;
  }
  updateTime();
}

function updateTime() {
  const total = Math.round(meta.timeSpent + (editable ? clock.pending : 0));
  $("#time-spent").textContent = `${Math.floor(total / 60)}:${String(total % 60).padStart(2, "0")}`;
}

let messageTimer = null;
function showMessage(text, kind = "info") {
  const el = $("#message");
  el.textContent = text;
  el.className = `message ${kind}`;
  el.hidden = false;
  clearTimeout(messageTimer);
  messageTimer = setTimeout(() => (el.hidden = true), kind === "error" ? 7000 : 4000);
}

function errorText(err) {
  if (err instanceof ApiError) {
    const fields = Object.entries(err.body?.fields || {}).map(([k, v]) => `${k}: ${v}`);
    return fields.length && !err.message.includes(fields[0].split(":")[0]) ? `${err.message} (${fields.join("; ")})` : err.message;
  }
  return err?.message || String(err);
}

async function setStatus(status, { thenGo = null } = {}) {
  pendingStatus = status;
  autosaver.changed();
  await autosaver.flush();
  if (thenGo && (meta.status === "done" || meta.status === "reviewed") && !autosaver.dirty) window.location.href = thenGo;
}

// Leave the page only once the last change is on the server.
async function leave(href) {
  await autosaver.flush();
  if (autosaver.dirty && !window.confirm("Your last changes are not saved yet. Leave anyway?")) return;
  window.location.href = href;
}

// ---------------------------------------------------------------- input

function screenPoint(event) {
  const r = canvas.getBoundingClientRect();
  return { x: event.clientX - r.left, y: event.clientY - r.top };
}

function onPointerDown(event) {
  canvas.setPointerCapture(event.pointerId);
  clock.input();
  const s = screenPoint(event);
  if (event.button === 1 || spaceHeld || tool === "pan") {
    drag = { type: "pan", last: s };
    canvas.classList.add("panning");
    event.preventDefault();
    return;
  }
  if (event.button !== 0 || !editable) return;
  const p = toImage(view, s.x, s.y);
  if (tool === "box") {
    drag = { type: "box", start: p, end: p };
  } else if (tool === "fg" || tool === "bg") {
    drag = { type: "stroke", label: tool, points: [toPixel(p)] };
  } else {
    const inst = target();
    const value = tool === "paint" ? 1 : 0;
    const point = toPixel(p);
    drag = { type: "paint", key: inst.key, value, last: point };
    const rect = paintSegment(inst.mask, W, H, point, point, brushRadius, value);
    if (rect) renderOverlay(rect);
  }
  draw();
}

function onPointerMove(event) {
  const s = screenPoint(event);
  pointer = s;
  clock.input();
  const p = toImage(view, s.x, s.y);
  $("#cursor-pos").textContent = p.x >= 0 && p.y >= 0 && p.x < W && p.y < H ? `${Math.floor(p.x)}, ${Math.floor(p.y)}` : "";
  if (!drag) {
    draw();
    return;
  }
  if (drag.type === "pan") {
    setView(pan(view, s.x - drag.last.x, s.y - drag.last.y));
    drag.last = s;
  } else if (drag.type === "box") {
    drag.end = p;
  } else if (drag.type === "stroke") {
    const q = toPixel(p);
    const last = drag.points[drag.points.length - 1];
    // Keep points about a screen pixel apart: enough for the shape, few to send.
    if (Math.hypot(q.x - last.x, q.y - last.y) * view.scale >= 2 && drag.points.length < 4000) drag.points.push(q);
  } else if (drag.type === "paint") {
    const inst = instance(drag.key);
    const q = toPixel(p);
    const rect = inst && paintSegment(inst.mask, W, H, drag.last, q, brushRadius, drag.value);
    drag.last = q;
    if (rect) renderOverlay(rect);
  }
  draw();
}

function onPointerUp() {
  const done = drag;
  drag = null;
  canvas.classList.remove("panning");
  if (!done) return;
  if (done.type === "box") {
    const box = dragBox(done.start, done.end, W, H);
    if (box) runGrabcut("box", { box });
  } else if (done.type === "stroke") {
    const inst = selected();
    if (!inst || !inst.engine) {
      showMessage("Draw a box around the object first (B): GrabCut strokes refine a box.", "error");
    } else {
      // Points far off the frame change nothing inside it; the server refuses them.
      const clamp = (v, size) => Math.min(size + 2 * brushRadius, Math.max(-2 * brushRadius, v));
      runGrabcut("stroke", {
        points: done.points.map((q) => [Math.round(clamp(q.x, W) * 100) / 100, Math.round(clamp(q.y, H) * 100) / 100]),
        label: done.label,
        radius: brushRadius,
      });
    }
  } else if (done.type === "paint") {
    commit();
  }
  draw();
}

function onWheel(event) {
  event.preventDefault();
  clock.input();
  const s = screenPoint(event);
  setView(zoomAt(view, wheelFactor(event.deltaY, event.deltaMode), s.x, s.y));
}

function zoomBy(factor) {
  setView(zoomAt(view, factor, stage.clientWidth / 2, stage.clientHeight / 2));
}

function onKeyDown(event) {
  if (event.target.closest?.("input, textarea, select")) {
    if (event.key === "Escape") event.target.blur();
    return;
  }
  clock.input();
  const key = event.key.toLowerCase();
  const mod = event.ctrlKey || event.metaKey;
  if (key === " ") {
    spaceHeld = true;
    canvas.classList.add("pan-ready");
    event.preventDefault();
    return;
  }
  if (mod && key === "z") {
    event.preventDefault();
    if (event.shiftKey) redo();
    else undo();
    return;
  }
  if (mod && key === "y") {
    event.preventDefault();
    redo();
    return;
  }
  if (mod && key === "s") {
    event.preventDefault();
    autosaver.flush();
    return;
  }
  if (mod && key === "enter" && editable) {
    event.preventDefault();
    setStatus("done", { thenGo: config.urls.next_unlabelled });
    return;
  }
  if (mod || event.altKey) return;
  const toolKey = Object.entries(TOOLS).find(([, k]) => k === key);
  if (toolKey) return setTool(toolKey[0]);
  if (key === "[") return setBrush(brushRadius / 1.25);
  if (key === "]") return setBrush(brushRadius * 1.25);
  if (key === "d") return cycleView();
  if (key === "m") return setShowMask(!showMask);
  if (key === "0") return fitView();
  if (key === "+" || key === "=") return zoomBy(1.25);
  if (key === "-") return zoomBy(0.8);
  if (key === "n" && editable) return addInstance();
  if (/^[1-9]$/.test(key)) return select(doc.instances[Number(key) - 1]?.key);
  if ((key === "delete" || key === "backspace") && editable && selectedKey) return deleteInstance(selectedKey);
  if (key === "arrowleft" && config.urls.previous) return leave(config.urls.previous);
  if (key === "arrowright" && config.urls.next) return leave(config.urls.next);
  if (key === "u" && config.urls.next_unlabelled) return leave(config.urls.next_unlabelled);
  if (!editable && key === "a") return review("accept");
  if (!editable && key === "r") return $("#review-comment").focus();
}

function onKeyUp(event) {
  if (event.key === " " && !event.target.closest?.("input, textarea, select")) {
    event.preventDefault(); // a focused button would take the space as a click
    spaceHeld = false;
    canvas.classList.remove("pan-ready");
  }
}

// ---------------------------------------------------------------- review mode

async function review(decision) {
  const comment = $("#review-comment").value.trim();
  try {
    await api("POST", config.urls.review, { version: meta.version, decision, comment: comment || null });
    window.location.href = config.urls.next_review;
  } catch (err) {
    showMessage(errorText(err), "error");
  }
}

// ---------------------------------------------------------------- wiring

function wire() {
  new ResizeObserver(resize).observe(stage);
  canvas.addEventListener("pointerdown", onPointerDown);
  canvas.addEventListener("pointermove", onPointerMove);
  canvas.addEventListener("pointerup", onPointerUp);
  canvas.addEventListener("pointercancel", onPointerUp);
  canvas.addEventListener("pointerleave", () => {
    pointer = null;
    draw();
  });
  canvas.addEventListener("wheel", onWheel, { passive: false });
  canvas.addEventListener("auxclick", (e) => e.preventDefault());
  document.addEventListener("keydown", onKeyDown);
  document.addEventListener("keyup", onKeyUp);
  $$("[data-tool]").forEach((b) => b.addEventListener("click", () => setTool(b.dataset.tool)));
  // Tool and zoom buttons give the keyboard back to the canvas (Space pans, it must not click them).
  $$(".toolbar button, .zoom button").forEach((b) => b.addEventListener("click", () => b.blur()));
  $$("[data-view]").forEach((b) => b.addEventListener("click", () => setBaseView(b.dataset.view)));
  $("#show-mask").addEventListener("change", (e) => setShowMask(e.target.checked));
  $("#opacity").addEventListener("input", (e) => {
    opacity = Number(e.target.value) / 100;
    draw();
  });
  $("#zoom-fit").addEventListener("click", fitView);
  $("#zoom-in").addEventListener("click", () => zoomBy(1.25));
  $("#zoom-out").addEventListener("click", () => zoomBy(0.8));
  $$("a[data-flush]").forEach((a) =>
    a.addEventListener("click", (e) => {
      e.preventDefault();
      leave(a.href);
    }),
  );
  if (editable) {
    $("#brush-size").addEventListener("input", (e) => setBrush(Number(e.target.value)));
    $("#undo").addEventListener("click", undo);
    $("#redo").addEventListener("click", redo);
    $("#add-instance").addEventListener("click", addInstance);
    $("#no-ao").addEventListener("change", (e) => {
      const drawn = doc.instances.filter((i) => i.mask.some((v) => v)).length;
      if (e.target.checked && drawn && !window.confirm(`Delete the ${drawn} drawn object(s) and mark the frame "no action-object"?`)) {
        e.target.checked = false;
        return;
      }
      doc.noActionObject = e.target.checked;
      if (doc.noActionObject) {
        doc.instances = [];
        selectedKey = null;
      }
      commit();
    });
    $("#mark-done").addEventListener("click", () => setStatus("done"));
    $("#done-next").addEventListener("click", () => setStatus("done", { thenGo: config.urls.next_unlabelled }));
    $("#reopen").addEventListener("click", () => setStatus("in_progress"));
    $("#reload-theirs").addEventListener("click", reloadTheirs);
    $("#keep-mine").addEventListener("click", keepMine);
    $("#save-now").addEventListener("click", () => autosaver.flush());
    // Time on the frame: counted while visible and active; flushed with the saves.
    setInterval(() => {
      clock.tick(document.visibilityState === "visible");
      updateTime();
      if (autosaver.retryAt !== null) showSaveState(); // the countdown to the next try
    }, 1000);
    // Leaving or hiding the page: unsaved edits go now; so does the time
    // counted since the last save, on its own (it makes no new version).
    const flushOnHide = () => {
      if (autosaver.dirty) {
        keepalive = true;
        autosaver.flush().finally(() => (keepalive = false));
      } else if (meta.version > 0 && clock.pending >= 1) {
        const seconds = clock.take();
        api("POST", config.urls.time, { seconds: Math.round(Math.min(seconds, 3600) * 1000) / 1000 }, { keepalive: true })
          .then(() => (meta.timeSpent += seconds))
          .catch(() => clock.giveBack(seconds));
      }
    };
    document.addEventListener("visibilitychange", () => {
      if (document.visibilityState === "hidden") flushOnHide();
      // Back from another tab (perhaps signed in again there): try a failed save now.
      else if (autosaver.retryAt !== null) autosaver.flush();
    });
    window.addEventListener("pagehide", flushOnHide);
    window.addEventListener("beforeunload", (e) => {
      if (autosaver.dirty) {
        flushOnHide();
        e.preventDefault();
      }
    });
  } else {
    $("#accept").addEventListener("click", () => review("accept"));
    $("#reject").addEventListener("click", () => review("reject"));
  }
}

// For tests and the console: what the page holds, without reaching into it.
window.labelPage = {
  get version() {
    return meta.version;
  },
  get saveState() {
    return autosaver.state;
  },
  instances: () => doc.instances.map((i) => ({ key: i.key, kind: i.kind, label: i.label, area: countSet(i.mask), hasEngine: !!i.engine })),
  maskRle: (k) => encodeCocoRle(doc.instances[k].mask, W, H),
  // Where image point (x, y) is in the window (for driving the page from tests).
  clientPoint: (x, y) => {
    const s = toScreen(view, x, y);
    const r = canvas.getBoundingClientRect();
    return { x: r.left + s.x, y: r.top + s.y };
  },
};

async function start() {
  wire();
  setTool(tool);
  setBrush(brushRadius);
  setBaseView("rgb");
  try {
    await loadAnnotation();
  } catch (err) {
    showMessage(`Could not load the annotation: ${errorText(err)}`, "error");
  }
  renderOverlay();
  renderInstances();
  updateControls();
  $("#label-app").dataset.ready = "1";
}

start();
