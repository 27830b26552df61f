// The labelling page's tools and what the pointer does with them: pan, box
// and fg/bg strokes (GrabCut), paint and erase by hand, the polygon, the
// brush radius, and the wheel's zoom. The box tool also edits the selected
// object's box (label_shapes.js). While the page is read-only (a done frame
// before "Edit", the review page before "Fix the mask") only panning and
// zooming work, and a drag says why nothing else does.

import { dragBox, pan, toImage, toPixel, wheelFactor, zoomAt } from "./geometry.js";
import { depthChoice } from "./label_depth.js";
import { runGrabcut } from "./label_grabcut.js";
import { addInstance, commit } from "./label_instances.js";
import { showMessage } from "./label_panel.js";
import { boxDrag, hoverBox, polygonClick, polygonDoubleClick } from "./label_shapes.js";
import { $, $$, H, W, clock, doc, editable, instance, reviewing, selected, target, ui } from "./label_state.js";
import { canvas, draw, renderOverlay, setView, view } from "./label_view.js";
import { paintSegment } from "./raster.js";

// Each tool's key.
export const TOOLS = { box: "b", fg: "f", bg: "g", paint: "p", erase: "e", polygon: "l", pan: "h" };

const HINTS = {
  box: "Drag a box around the object: GrabCut outlines it. Drag the selected object's box edges or handles to cut it again; a drag inside it draws a new object.",
  fg: "Paint over parts that belong to the object (GrabCut).",
  bg: "Paint over background that was taken in (GrabCut).",
  paint: "Paint the mask by hand.",
  erase: "Erase the mask by hand.",
  polygon: "Click the object's corners; click the first one again (or Enter, or double-click) to fill it. Backspace drops a corner, Esc cancels.",
  pan: "Drag to move the image.",
};

// Why the canvas does not take an edit now.
export function readOnlyReason() {
  return reviewing
    ? "Read-only: press “Fix the mask” to change this annotation before you decide."
    : "This frame is finished and read-only: press Edit (above the image) to change it.";
}

export function setTool(name) {
  if (name !== "polygon") ui.polygon = null;
  canvas.style.cursor = ""; // the box handles' cursor, if any
  ui.tool = name;
  $$("[data-tool]").forEach((b) => b.classList.toggle("active", b.dataset.tool === ui.tool));
  canvas.dataset.tool = ui.tool;
  $("#tool-hint").textContent = HINTS[ui.tool];
  draw();
}

export function setBrush(radius) {
  ui.brushRadius = Math.min(200, Math.max(1, Math.round(radius)));
  const input = $("#brush-size");
  if (input) input.value = ui.brushRadius;
  const value = $("#brush-size-value");
  if (value) value.textContent = `${ui.brushRadius}px`;
  draw();
}

// A new object, ready for its box.
export function newObject() {
  addInstance();
  setTool("box");
}

// Space held: the pointer pans whatever the tool.
export function holdSpace(held) {
  ui.spaceHeld = held;
  canvas.classList.toggle("pan-ready", held);
}

function screenPoint(event) {
  const r = canvas.getBoundingClientRect();
  return { x: event.clientX - r.left, y: event.clientY - r.top };
}

function onPointerDown(event) {
  canvas.setPointerCapture(event.pointerId);
  clock.input();
  const s = screenPoint(event);
  if (event.button === 1 || ui.spaceHeld || ui.tool === "pan") {
    ui.drag = { type: "pan", last: s };
    canvas.classList.add("panning");
    event.preventDefault();
    return;
  }
  if (event.button !== 0) return;
  if (!editable) {
    showMessage(readOnlyReason(), "info");
    return;
  }
  const p = toImage(view, s.x, s.y);
  if (ui.tool === "box") {
    ui.drag = boxDrag(s, p) || { type: "box", start: p, end: p };
  } else if (ui.tool === "polygon") {
    polygonClick(p, s, event.detail);
  } else if (ui.tool === "fg" || ui.tool === "bg") {
    ui.drag = { type: "stroke", label: ui.tool, points: [toPixel(p)] };
  } else {
    const inst = target();
    const value = ui.tool === "paint" ? 1 : 0;
    const point = toPixel(p);
    ui.drag = { type: "paint", key: inst.key, value, last: point };
    const rect = paintSegment(inst.mask, W, H, point, point, ui.brushRadius, value);
    if (rect) renderOverlay(rect);
  }
  draw();
}

function onPointerMove(event) {
  const s = screenPoint(event);
  ui.pointer = s;
  clock.input();
  const p = toImage(view, s.x, s.y);
  $("#cursor-pos").textContent = p.x >= 0 && p.y >= 0 && p.x < W && p.y < H ? `${Math.floor(p.x)}, ${Math.floor(p.y)}` : "";
  const drag = ui.drag;
  if (!drag) {
    if (ui.tool === "box") hoverBox(s);
    draw();
    return;
  }
  if (drag.type === "pan") {
    setView(pan(view, s.x - drag.last.x, s.y - drag.last.y));
    drag.last = s;
  } else if (drag.type === "box") {
    drag.end = p;
  } else if (drag.type === "edit-box") {
    drag.move(p);
  } else if (drag.type === "stroke") {
    const q = toPixel(p);
    const last = drag.points[drag.points.length - 1];
    // Keep points about a screen pixel apart: enough for the shape, few to send.
    if (Math.hypot(q.x - last.x, q.y - last.y) * view.scale >= 2 && drag.points.length < 4000) drag.points.push(q);
  } else if (drag.type === "paint") {
    const inst = instance(drag.key);
    const q = toPixel(p);
    const rect = inst && paintSegment(inst.mask, W, H, drag.last, q, ui.brushRadius, drag.value);
    drag.last = q;
    if (rect) renderOverlay(rect);
  }
  draw();
}

function onPointerUp() {
  const done = ui.drag;
  ui.drag = null;
  canvas.classList.remove("panning");
  if (!done) return;
  if (done.type === "box") {
    const box = dragBox(done.start, done.end, W, H);
    if (box) {
      const selectedBefore = ui.selectedKey;
      const before = new Set(doc.instances.map((i) => i.key));
      const { key } = target({ fresh: true });
      runGrabcut("box", { box, ...depthChoice() }, key, { made: !before.has(key), selectedBefore });
    }
  } else if (done.type === "edit-box") {
    done.finish();
  } else if (done.type === "stroke") {
    const inst = selected();
    if (!inst || (!inst.engine && !inst.mask.includes(1))) {
      showMessage("Draw a box around the object first (B), or paint it (P): GrabCut strokes correct an object's mask.", "error");
    } else {
      // Points far off the frame change nothing inside it; the server refuses them.
      const r = ui.brushRadius;
      const clamp = (v, size) => Math.min(size + 2 * r, Math.max(-2 * r, v));
      runGrabcut("stroke", {
        points: done.points.map((q) => [Math.round(clamp(q.x, W) * 100) / 100, Math.round(clamp(q.y, H) * 100) / 100]),
        label: done.label,
        radius: r,
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

export function wireTools() {
  canvas.addEventListener("pointerdown", onPointerDown);
  canvas.addEventListener("pointermove", onPointerMove);
  canvas.addEventListener("pointerup", onPointerUp);
  canvas.addEventListener("pointercancel", onPointerUp);
  canvas.addEventListener("pointerleave", () => {
    ui.pointer = null;
    draw();
  });
  canvas.addEventListener("wheel", onWheel, { passive: false });
  canvas.addEventListener("dblclick", () => editable && ui.tool === "polygon" && polygonDoubleClick());
  canvas.addEventListener("auxclick", (e) => e.preventDefault());
  $$("[data-tool]").forEach((b) => b.addEventListener("click", () => setTool(b.dataset.tool)));
  $("#brush-size").addEventListener("input", (e) => setBrush(Number(e.target.value)));
}
