// The canvas view: image pixels <-> screen pixels, zoom and pan.
//
// A view is {scale, tx, ty}: screen = image * scale + t. Image coordinates
// are continuous: pixel (i, j) covers [i, i + 1) x [j, j + 1), so its centre
// is (i + 0.5, j + 0.5). The GrabCut engine puts pixel centres at integers,
// which toPixel() converts to.

export const MIN_SCALE = 0.05;
export const MAX_SCALE = 32;

export function clampScale(scale) {
  return Math.min(MAX_SCALE, Math.max(MIN_SCALE, scale));
}

// The whole image centred in a viewport, with a margin in screen pixels.
export function fit(viewWidth, viewHeight, imageWidth, imageHeight, margin = 16) {
  const scale = clampScale(
    Math.min((viewWidth - 2 * margin) / imageWidth, (viewHeight - 2 * margin) / imageHeight),
  );
  return { scale, tx: (viewWidth - imageWidth * scale) / 2, ty: (viewHeight - imageHeight * scale) / 2 };
}

export function toImage(view, sx, sy) {
  return { x: (sx - view.tx) / view.scale, y: (sy - view.ty) / view.scale };
}

export function toScreen(view, x, y) {
  return { x: x * view.scale + view.tx, y: y * view.scale + view.ty };
}

// Engine coordinates of an image point: the pixel centres sit at integers.
export function toPixel(point) {
  return { x: point.x - 0.5, y: point.y - 0.5 };
}

// Zoom by `factor` keeping the image point under (sx, sy) where it is.
export function zoomAt(view, factor, sx, sy) {
  const scale = clampScale(view.scale * factor);
  const p = toImage(view, sx, sy);
  return { scale, tx: sx - p.x * scale, ty: sy - p.y * scale };
}

export function pan(view, dx, dy) {
  return { scale: view.scale, tx: view.tx + dx, ty: view.ty + dy };
}

// Wheel delta (pixels or lines) -> zoom factor; one notch of a mouse wheel is about 10%.
export function wheelFactor(deltaY, deltaMode = 0) {
  const pixels = deltaMode === 1 ? deltaY * 33 : deltaMode === 2 ? deltaY * 800 : deltaY;
  return Math.exp(-pixels * 0.001);
}

// The box dragged from a to b (image coordinates) as pixel bounds [x0, y0, x1, y1)
// clipped to the image, or null when nothing of the image is inside.
export function dragBox(a, b, width, height) {
  const x0 = Math.max(0, Math.floor(Math.min(a.x, b.x)));
  const y0 = Math.max(0, Math.floor(Math.min(a.y, b.y)));
  const x1 = Math.min(width, Math.ceil(Math.max(a.x, b.x)));
  const y1 = Math.min(height, Math.ceil(Math.max(a.y, b.y)));
  if (x1 - x0 < 2 || y1 - y0 < 2) return null;
  return [x0, y0, x1, y1];
}

// After the viewport changed size (a banner came or went, the window was
// resized): keep the image point that was at the viewport's centre there.
export function recentre(view, oldWidth, oldHeight, newWidth, newHeight) {
  return { scale: view.scale, tx: view.tx + (newWidth - oldWidth) / 2, ty: view.ty + (newHeight - oldHeight) / 2 };
}

// Which part of box [x0, y0, x1, y1) (image pixels) the screen point (sx, sy)
// grabs: a corner ("nw", "ne", "se", "sw"), an edge ("n", "e", "s", "w"),
// the inside ("move"), or null; `grip` is how near (screen pixels) counts.
export function boxHit(view, box, sx, sy, grip = 7) {
  const a = toScreen(view, box[0], box[1]);
  const b = toScreen(view, box[2], box[3]);
  if (sx < a.x - grip || sx > b.x + grip || sy < a.y - grip || sy > b.y + grip) return null;
  const near = (v, edge) => Math.abs(v - edge) <= grip;
  const ns = near(sy, a.y) ? "n" : near(sy, b.y) ? "s" : "";
  const we = near(sx, a.x) ? "w" : near(sx, b.x) ? "e" : "";
  if (ns || we) return ns + we;
  return sx > a.x && sx < b.x && sy > a.y && sy < b.y ? "move" : null;
}

// The box after dragging its part `hit` by (dx, dy) image pixels: whole
// pixels, inside the width x height image, at least 2 pixels a side.
export function editBox(box, hit, dx, dy, width, height) {
  let [x0, y0, x1, y1] = box;
  if (hit === "move") {
    const mx = Math.round(Math.min(width - x1, Math.max(-x0, dx)));
    const my = Math.round(Math.min(height - y1, Math.max(-y0, dy)));
    return [x0 + mx, y0 + my, x1 + mx, y1 + my];
  }
  if (hit.includes("w")) x0 = Math.min(x1 - 2, Math.max(0, Math.round(x0 + dx)));
  if (hit.includes("e")) x1 = Math.max(x0 + 2, Math.min(width, Math.round(x1 + dx)));
  if (hit.includes("n")) y0 = Math.min(y1 - 2, Math.max(0, Math.round(y0 + dy)));
  if (hit.includes("s")) y1 = Math.max(y0 + 2, Math.min(height, Math.round(y1 + dy)));
  return [x0, y0, x1, y1];
}

// The CSS cursor for a part of a box.
export function boxCursor(hit) {
  return { n: "ns-resize", s: "ns-resize", e: "ew-resize", w: "ew-resize", nw: "nwse-resize", se: "nwse-resize", ne: "nesw-resize", sw: "nesw-resize", move: "move" }[hit] || "";
}
