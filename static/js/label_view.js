// The labelling page's canvas: the frame (RGB, depth or DHG) under the
// objects' masks, zoomed and panned, with what is being drawn on top.
//
// The masks are kept as two image-sized canvases (each object's fill, the
// selected one's outline) that renderOverlay() recolours only where an edit
// touched; draw() repaints the screen once per animation frame.

import { fit, toScreen, zoomAt } from "./geometry.js";
import { $, $$, H, W, config, doc, editable, ui } from "./label_state.js";

export const canvas = $("#canvas");
export const stage = $("#stage");
export let view = { scale: 1, tx: 0, ty: 0 };
export let showMask = true;
// Extra layers other modules draw over the masks, in screen pixels: painter(ctx, view).
export const painters = [];

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
let opacity = 0.5;
let fitted = false;
let currentView = "rgb";
let frameRequested = false;

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
export function renderOverlay(rect = { x0: 0, y0: 0, x1: W, y1: H }) {
  const x0 = Math.max(0, rect.x0 - 1);
  const y0 = Math.max(0, rect.y0 - 1);
  const x1 = Math.min(W, rect.x1 + 1);
  const y1 = Math.min(H, rect.y1 + 1);
  if (x0 >= x1 || y0 >= y1) return;
  const f = fillData.data;
  const e = edgeData.data;
  const list = doc.instances;
  const sel = list.findIndex((i) => i.key === ui.selectedKey);
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

export function draw() {
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
  if (showMask) painters.forEach((painter) => painter(ctx, view));
  paintPreview();
}

// What is being drawn right now, and the brush outline, in screen pixels.
function paintPreview() {
  const { drag, pointer, tool, brushRadius } = ui;
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
  if (pointer && editable && ["fg", "bg", "paint", "erase"].includes(tool) && !ui.spaceHeld) {
    ctx.strokeStyle = { fg: "#3cdc5a", bg: "#ff4646", paint: "#ffffff", erase: "#ffffff" }[tool];
    ctx.lineWidth = 1.5;
    ctx.setLineDash(tool === "erase" ? [3, 3] : []);
    ctx.beginPath();
    ctx.arc(pointer.x, pointer.y, Math.max(2, brushRadius * view.scale), 0, 2 * Math.PI);
    ctx.stroke();
    ctx.setLineDash([]);
  }
}

export function resize() {
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

export function fitView() {
  view = fit(stage.clientWidth, stage.clientHeight, W, H);
  updateZoomLabel();
  draw();
}

export function setView(next) {
  view = next;
  updateZoomLabel();
  draw();
}

export function zoomBy(factor) {
  setView(zoomAt(view, factor, stage.clientWidth / 2, stage.clientHeight / 2));
}

function updateZoomLabel() {
  $("#zoom-value").textContent = `${Math.round(view.scale * 100)}%`;
}

export function setBaseView(name) {
  if (!config.frame[`${name}_url`]) return;
  currentView = name;
  $$("[data-view]").forEach((b) => b.classList.toggle("active", b.dataset.view === name));
  baseImage(name);
  draw();
}

export function cycleView() {
  const names = ["rgb", "depth", "dhg"].filter((n) => config.frame[`${n}_url`]);
  setBaseView(names[(names.indexOf(currentView) + 1) % names.length]);
}

export function setShowMask(on) {
  showMask = on;
  $("#show-mask").checked = on;
  draw();
}

export function setOpacity(value) {
  opacity = value;
  draw();
}

// Where image point (x, y) is in the window.
export function clientPoint(x, y) {
  const s = toScreen(view, x, y);
  const r = canvas.getBoundingClientRect();
  return { x: r.left + s.x, y: r.top + s.y };
}
