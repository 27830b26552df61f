// Frame viewer: every annotation's objects outlined in their colours over the
// RGB, depth and DHG views (toggled per annotation, per object, or all with O),
// the prediction's colour bar and its display-only "stretch to this map's
// range" switch; arrow keys move to the previous / next frame.
import { scaleTicks } from "./heat_scale.js";
import { boundingBox } from "./raster.js";
import { maskFromRGBA, outlineBand, paintBand, placeTag, tagText, thicknessFor } from "./outline.js";

const config = JSON.parse(document.getElementById("viewer-config").textContent);
const { width: W, height: H } = config.frame;
const canvases = [...document.querySelectorAll("canvas.outlines")];
const master = document.getElementById("show-outlines");
const TAG_FONT_PX = 12; // on screen

// {annotation, position, number, kind, colour, mask, box, band, shown}
const objects = config.annotations.flatMap((a) =>
  a.instances.map((i, k) => ({ annotation: a.id, position: i.position, number: k + 1, kind: i.kind, colour: i.colour, url: i.mask_url, shown: a.shown, mask: null, band: null, box: null })),
);
let thickness = 0;

async function loadMask(url) {
  const image = new Image();
  image.src = url;
  await image.decode();
  const canvas = document.createElement("canvas");
  canvas.width = W;
  canvas.height = H;
  const ctx = canvas.getContext("2d", { willReadFrequently: true });
  ctx.drawImage(image, 0, 0, W, H);
  return maskFromRGBA(ctx.getImageData(0, 0, W, H).data, W, H);
}

function shownWidth() {
  return canvases.length ? canvases[0].getBoundingClientRect().width : W;
}

// Outline each object so it looks 2 px wide at the views' size; true when that changed.
function updateBands({ force = false } = {}) {
  const t = thicknessFor(W, shownWidth());
  if (t === thickness && !force) return false;
  thickness = t;
  for (const o of objects) if (o.mask) o.band = outlineBand(o.mask, W, H, thickness);
  return true;
}

function drawTag(ctx, o, scale, placed) {
  if (!o.box) return;
  const text = tagText(o.number, o.kind);
  const size = TAG_FONT_PX * scale;
  ctx.font = `600 ${size}px system-ui, sans-serif`;
  const pad = 3 * scale;
  const w = ctx.measureText(text).width + 2 * pad;
  const h = size + 2 * pad;
  const { x, y } = placeTag(o.box, w, h, W, H, placed);
  ctx.fillStyle = `rgb(${o.colour.join(",")})`;
  ctx.fillRect(x, y, w, h);
  ctx.fillStyle = "#111";
  ctx.textBaseline = "top";
  ctx.fillText(text, x + pad, y + pad);
}

function draw() {
  const visible = master && !master.checked ? [] : objects.filter((o) => o.shown && o.band);
  const picture = new ImageData(W, H);
  for (const o of visible) paintBand(picture.data, o.band, o.colour);
  const scale = W / shownWidth();
  for (const canvas of canvases) {
    const ctx = canvas.getContext("2d");
    ctx.putImageData(picture, 0, 0);
    const placed = [];
    for (const o of visible) drawTag(ctx, o, scale, placed);
  }
  document.getElementById("views").dataset.outlines = String(visible.length);
}

function wireToggles() {
  master?.addEventListener("change", draw);
  for (const box of document.querySelectorAll(".show-annotation")) {
    box.addEventListener("change", () => {
      for (const o of objects) if (String(o.annotation) === box.dataset.annotation) o.shown = box.checked;
      for (const sub of document.querySelectorAll(`.show-instance[data-annotation="${box.dataset.annotation}"]`)) sub.checked = box.checked;
      draw();
    });
  }
  for (const box of document.querySelectorAll(".show-instance")) {
    box.addEventListener("change", () => {
      const o = objects.find((x) => String(x.annotation) === box.dataset.annotation && String(x.position) === box.dataset.position);
      if (o) o.shown = box.checked;
      draw();
    });
  }
  for (const swatch of document.querySelectorAll(".swatch")) swatch.style.backgroundColor = `rgb(${swatch.dataset.colour})`;
  new ResizeObserver(() => updateBands() && draw()).observe(document.getElementById("views"));
}

function wirePrediction() {
  const p = config.prediction;
  const normalise = document.getElementById("normalise-prediction");
  if (!p || !normalise) return;
  const overlay = document.getElementById("view-prediction");
  const show = document.getElementById("show-prediction");
  normalise.addEventListener("change", () => {
    const stretched = normalise.checked && p.normalised_url;
    overlay.src = stretched ? p.normalised_url : p.overlay_url;
    const ticks = stretched ? scaleTicks(p.low, p.high) : scaleTicks(0, 1);
    document.querySelectorAll("#heat-ticks span").forEach((span, i) => (span.textContent = ticks[i]));
    document.getElementById("heat-caption").textContent = stretched
      ? "stretched to this map's range (display only)"
      : "action-object probability";
    document.getElementById("heat-scale").dataset.scale = stretched ? "map" : "probability";
    if (stretched) show.checked = true; // stretching something hidden would show nothing
  });
}

document.addEventListener("keydown", (event) => {
  // Keys typed into a field are its own (a ticked box takes none of these).
  if (event.target.closest("input:not([type=checkbox]), textarea, select") || event.ctrlKey || event.metaKey || event.altKey) return;
  if ((event.key === "o" || event.key === "O") && master) {
    master.checked = !master.checked;
    draw();
    return;
  }
  const link = { ArrowLeft: "prev", ArrowRight: "next" }[event.key];
  const anchor = link && document.getElementById(link);
  if (anchor) anchor.click();
});

async function start() {
  wireToggles();
  wirePrediction();
  await Promise.all(
    objects.map(async (o) => {
      try {
        o.mask = await loadMask(o.url);
        o.box = boundingBox(o.mask, W, H);
      } catch (error) {
        console.warn("mask", o.url, error);
      }
    }),
  );
  updateBands({ force: true });
  draw();
  document.getElementById("views").dataset.ready = "1";
}

start();
