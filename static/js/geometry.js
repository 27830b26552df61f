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
