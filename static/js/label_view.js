// The labelling page's canvas: the frame (RGB, depth or DHG, with the
// display's brightness and contrast) under the objects' masks, zoomed and
// panned, with what is being drawn on top.
//
// The masks are kept as two image-sized canvases (each object's fill; every
// object's outline in its own colour, with a dark rim outside it so it shows
// over any image, the DHG's colours included) that renderOverlay() recolours
// only where an edit touched; hidden objects are left out of both. draw()
// repaints the screen once per animation frame. The view fits the frame
// until the person zooms or pans; when the canvas changes size (a banner
// comes or goes, the window is resized) it fits again, or keeps its centre.

import { fit, recentre, toScreen, zoomAt } from "./geometry.js";
import { $, $$, H, W, config, doc, editable, ui } from "./label_state.js";

export const canvas = $("#canvas");
export const stage = $("#stage");
export let view = { scale: 1, tx: 0, ty: 0 };
export let showMask = true;
export const display = { brightness: 1, contrast: 1 };
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
let autoFit = true; // until the person zooms or pans
let stageSize = { w: 0, h: 0 };
let currentView = "rgb";
let frameRequested = false;
// Outlines this many image pixels wide: about a screen pixel on a large frame shown small.
const EDGE = Math.max(1, Math.round(W / 640));
const failedImages = new Set();

function baseImage(name) {
  if (!images[name]) {
    const img = new Image();
    img.onload = draw;
    img.onerror = () => {
      failedImages.add(name);
      document.dispatchEvent(new CustomEvent("label:image-failed", { detail: name }));
      draw();
    };
    img.src = config.frame[`${name}_url`];
    images[name] = img;
  }
  return images[name];
}

// The index of the visible object that shows at pixel i (the selected one on top), or -1.
function ownerAt(list, sel, i) {
  if (sel >= 0 && list[sel].mask[i] && !list[sel].hidden) return sel;
  for (let k = list.length - 1; k >= 0; k--) if (list[k].mask[i] && !list[k].hidden) return k;
  return -1;
}

// Recolour the overlay inside rect (image pixels): every visible object in
// its colour (the selected one on top and stronger), every outline in its
// object's colour (the selected one's twice as wide), a dark rim outside.
export function renderOverlay(rect = { x0: 0, y0: 0, x1: W, y1: H }) {
  const x0 = Math.max(0, rect.x0 - EDGE - 1);
  const y0 = Math.max(0, rect.y0 - EDGE - 1);
  const x1 = Math.min(W, rect.x1 + EDGE + 1);
  const y1 = Math.min(H, rect.y1 + EDGE + 1);
  if (x0 >= x1 || y0 >= y1) return;
  const f = fillData.data;
  const e = edgeData.data;
  const list = doc.instances;
  const sel = list.findIndex((i) => i.key === ui.selectedKey);
  const steps = [[-EDGE, 0], [EDGE, 0], [0, -EDGE], [0, EDGE]];
  for (let y = y0; y < y1; y++) {
    for (let x = x0; x < x1; x++) {
      const i = y * W + x;
      const p = 4 * i;
      const owner = ownerAt(list, sel, i);
      // The owners of the pixels EDGE away: this pixel is on an outline when one differs.
      let other = owner;
      for (const [dx, dy] of steps) {
        const nx = x + dx;
        const ny = y + dy;
        const o = nx < 0 || ny < 0 || nx >= W || ny >= H ? -1 : ownerAt(list, sel, ny * W + nx);
        if (o !== owner && (other === owner || o === sel)) other = o;
      }
      if (owner < 0) {
        f[p + 3] = 0;
      } else {
        const c = list[owner].colour;
        f[p] = c[0];
        f[p + 1] = c[1];
        f[p + 2] = c[2];
        f[p + 3] = owner === sel ? 255 : 150;
      }
      if (other === owner) {
        e[p + 3] = 0;
      } else if (owner >= 0) {
        const c = list[owner].colour; // inside an outline: the object's colour
        e[p] = c[0];
        e[p + 1] = c[1];
        e[p + 2] = c[2];
        e[p + 3] = 255;
      } else if (other === sel) {
        const c = list[sel].colour; // the selected object's outline is wider
        e[p] = c[0];
        e[p + 1] = c[1];
        e[p + 2] = c[2];
        e[p + 3] = 255;
      } else {
        e[p] = e[p + 1] = e[p + 2] = 0; // a dark rim outside the others
        e[p + 3] = 190;
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
  if (base.complete && base.naturalWidth) {
    if (display.brightness !== 1 || display.contrast !== 1) ctx.filter = `brightness(${display.brightness}) contrast(${display.contrast})`;
    ctx.drawImage(base, 0, 0, W, H);
    ctx.filter = "none";
    canvas.dataset.shown = currentView; // which image is on screen now (the buttons change before the next paint)
  } else {
    ctx.fillStyle = "#252a33";
    ctx.fillRect(0, 0, W, H);
  }
  if (showMask) {
    ctx.globalAlpha = opacity;
    ctx.drawImage(fillCanvas, 0, 0);
    ctx.globalAlpha = 1;
    const smooth = ctx.imageSmoothingEnabled;
    ctx.imageSmoothingEnabled = false; // outlines stay crisp, whatever the zoom
    ctx.drawImage(edgeCanvas, 0, 0);
    ctx.imageSmoothingEnabled = smooth;
  }
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  const corner = toScreen(view, 0, 0);
  ctx.strokeStyle = "rgba(255,255,255,0.25)";
  ctx.lineWidth = 1;
  ctx.strokeRect(corner.x - 0.5, corner.y - 0.5, W * view.scale + 1, H * view.scale + 1);
  if (showMask) painters.forEach((painter) => painter(ctx, view));
  paintPreview();
  if (failedImages.has(currentView)) {
    ctx.fillStyle = "#ff8787";
    ctx.font = "600 14px system-ui, sans-serif";
    ctx.fillText(`The ${currentView.toUpperCase()} image could not be loaded.`, corner.x + 12, corner.y + 24);
  }
}

// A GrabCut stroke through image pixels `points` ({x, y}): green for the
// object ("fg"), red for background, `alpha` opaque, in screen pixels.
export function paintStrokePath(points, label, radius, alpha) {
  ctx.save();
  ctx.strokeStyle = label === "fg" ? `rgba(60, 220, 90, ${alpha})` : `rgba(255, 70, 70, ${alpha})`;
  ctx.fillStyle = ctx.strokeStyle;
  ctx.lineWidth = Math.max(1, 2 * radius * view.scale);
  ctx.lineCap = ctx.lineJoin = "round";
  ctx.beginPath();
  points.forEach((p, i) => {
    const s = toScreen(view, p.x + 0.5, p.y + 0.5);
    if (i === 0) ctx.moveTo(s.x, s.y);
    else ctx.lineTo(s.x, s.y);
  });
  if (points.length === 1) {
    const s = toScreen(view, points[0].x + 0.5, points[0].y + 0.5);
    ctx.arc(s.x, s.y, radius * view.scale, 0, 2 * Math.PI);
    ctx.fill();
  } else ctx.stroke();
  ctx.restore();
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
  if (drag?.type === "stroke") paintStrokePath(drag.points, drag.label, brushRadius, 0.6);
  if (ui.polygon) paintPolygon(ui.polygon.points, pointer);
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

// The polygon being drawn: its corners, the side to the pointer, the first corner's ring (click it to close).
function paintPolygon(points, pointer) {
  if (!points.length) return;
  const screen = points.map((p) => toScreen(view, p.x, p.y));
  ctx.strokeStyle = "#ffe14d";
  ctx.fillStyle = "rgba(255, 225, 77, 0.18)";
  ctx.lineWidth = 2;
  ctx.beginPath();
  screen.forEach((s, i) => (i ? ctx.lineTo(s.x, s.y) : ctx.moveTo(s.x, s.y)));
  if (pointer) ctx.lineTo(pointer.x, pointer.y);
  if (screen.length > 2) ctx.fill();
  ctx.stroke();
  ctx.fillStyle = "#ffe14d";
  for (const s of screen) ctx.fillRect(s.x - 3, s.y - 3, 6, 6);
  ctx.beginPath();
  ctx.arc(screen[0].x, screen[0].y, 7, 0, 2 * Math.PI);
  ctx.stroke();
}

export function resize() {
  const dpr = window.devicePixelRatio || 1;
  const { clientWidth, clientHeight } = stage;
  canvas.width = Math.max(1, Math.round(clientWidth * dpr));
  canvas.height = Math.max(1, Math.round(clientHeight * dpr));
  canvas.style.width = `${clientWidth}px`;
  canvas.style.height = `${clientHeight}px`;
  if (clientWidth > 0 && clientHeight > 0) {
    if (!fitted || autoFit) fitView();
    else view = recentre(view, stageSize.w, stageSize.h, clientWidth, clientHeight);
    fitted = true;
    stageSize = { w: clientWidth, h: clientHeight };
  }
  draw();
}

export function fitView() {
  view = fit(stage.clientWidth, stage.clientHeight, W, H);
  autoFit = true;
  updateZoomLabel();
  draw();
}

// The person moved the view: it stays where they put it.
export function setView(next) {
  view = next;
  autoFit = false;
  updateZoomLabel();
  draw();
}

export function setDisplay({ brightness = display.brightness, contrast = display.contrast }) {
  display.brightness = brightness;
  display.contrast = contrast;
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
