// Shapes on the labelling page: the selected object's box, which the box
// tool moves and resizes (letting go cuts the object again with GrabCut,
// through the same box request as a new box), and the polygon tool, whose
// corners fill into the selected object's mask (or a new one's) by hand:
// good for thin objects that GrabCut's box misses.
//
// An object's box is the last GrabCut box drawn for it, else its mask's
// bounding box. A box drag that starts on the selected object's box edges or
// handles edits it; anywhere else, inside the box too, it draws a new
// object. (Moving the whole box, as drawing programs do, cut the object
// again from wherever the box landed: a drag meant as a new box inside it
// emptied the object. The box is GrabCut's input, not the annotation.)

import { boxCursor, boxHit, editBox, toPixel, toScreen } from "./geometry.js";
import { depthChoice } from "./label_depth.js";
import { runGrabcut } from "./label_grabcut.js";
import { commit } from "./label_instances.js";
import { showMessage } from "./label_panel.js";
import { H, W, editable, selected, target, ui } from "./label_state.js";
import { canvas, draw, painters, renderOverlay, view } from "./label_view.js";
import { boundingBox, fillPolygon } from "./raster.js";

const CLOSE_PX = 8; // a click this near the first corner closes the polygon
let cached = { key: null, box: null }; // the selected object's box, until the next redraw of the list

export function boxOf(inst) {
  if (!inst) return null;
  if (inst.box) return inst.box;
  if (cached.key !== inst.key) cached = { key: inst.key, box: boundingBox(inst.mask, W, H) };
  return cached.box;
}

function editableBox() {
  const inst = selected();
  if (!editable || ui.tool !== "box" || !inst || inst.hidden) return null;
  const box = boxOf(inst);
  return box ? { inst, box } : null;
}

// A press at screen point s (image point p) with the box tool: the drag that edits the selected box, or null.
export function boxDrag(s, p) {
  const found = editableBox();
  const hit = found && boxHit(view, found.box, s.x, s.y);
  if (!hit || hit === "move") return null;
  const { inst, box } = found;
  return {
    type: "edit-box",
    key: inst.key,
    current: box,
    move(q) {
      this.current = editBox(box, hit, q.x - p.x, q.y - p.y, W, H);
    },
    finish() {
      if (this.current.every((v, k) => v === box[k])) return; // a click, not a drag
      runGrabcut("box", { box: this.current, ...depthChoice() }, inst.key);
    },
  };
}

// The cursor over the selected box's handles.
export function hoverBox(s) {
  const found = editableBox();
  const hit = found && boxHit(view, found.box, s.x, s.y);
  canvas.style.cursor = hit && hit !== "move" ? boxCursor(hit) : "";
}

function paintBox(ctx) {
  const found = editableBox();
  if (!found) return;
  const box = ui.drag?.type === "edit-box" ? ui.drag.current : found.box;
  const a = toScreen(view, box[0], box[1]);
  const b = toScreen(view, box[2], box[3]);
  const colour = `rgb(${found.inst.colour.join(", ")})`;
  ctx.save();
  ctx.setLineDash([5, 4]);
  ctx.lineWidth = 1.5;
  ctx.strokeStyle = colour;
  ctx.strokeRect(a.x, a.y, b.x - a.x, b.y - a.y);
  ctx.setLineDash([]);
  const mx = (a.x + b.x) / 2;
  const my = (a.y + b.y) / 2;
  for (const [x, y] of [[a.x, a.y], [mx, a.y], [b.x, a.y], [b.x, my], [b.x, b.y], [mx, b.y], [a.x, b.y], [a.x, my]]) {
    ctx.fillStyle = "#fff";
    ctx.fillRect(x - 4, y - 4, 8, 8);
    ctx.strokeStyle = colour;
    ctx.strokeRect(x - 4, y - 4, 8, 8);
  }
  ctx.restore();
}

// --------------------------------------------------------------------------
// The polygon

// A click with the polygon tool at image point p (screen point s); `clicks` is the event's detail.
export function polygonClick(p, s, clicks) {
  if (clicks > 1) return; // the second click of a double-click: dblclick closes
  const poly = ui.polygon;
  if (!poly) {
    ui.polygon = { points: [p] };
  } else {
    const first = toScreen(view, poly.points[0].x, poly.points[0].y);
    if (poly.points.length >= 3 && Math.hypot(s.x - first.x, s.y - first.y) <= CLOSE_PX) closePolygon();
    else poly.points.push(p);
  }
  draw();
}

export function polygonDoubleClick() {
  closePolygon();
}

// Fill the polygon into the target object's mask, as one undoable edit.
export function closePolygon() {
  const poly = ui.polygon;
  if (!poly) return;
  if (poly.points.length < 3) {
    showMessage("A polygon needs at least three corners: click around the object.", "info");
    return;
  }
  ui.polygon = null;
  const inst = target();
  const rect = fillPolygon(inst.mask, W, H, poly.points.map(toPixel), 1);
  if (rect) renderOverlay(rect);
  commit();
}

// Enter, Escape and Backspace while a polygon is being drawn; true when the key was for it.
export function polygonKey(key) {
  const poly = ui.polygon;
  if (!poly) return false;
  if (key === "enter") closePolygon();
  else if (key === "escape") ui.polygon = null;
  else if (key === "backspace") {
    poly.points.pop();
    if (!poly.points.length) ui.polygon = null;
  } else return false;
  draw();
  return true;
}

painters.push(paintBox);
document.addEventListener("label:instances-rendered", () => (cached = { key: null, box: null }));
