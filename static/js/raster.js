// Painting brush strokes into a binary mask (Uint8Array, row by row).
//
// The footprint is the GrabCut engine's (egonet.grabcut.stroke_footprint):
// pixel (x, y), with pixel centres at integer coordinates, is covered when
// its distance to the polyline is at most the radius. Painting on the page
// and strokes on the server therefore cover the same pixels.

// Paint the segment a-b; returns the touched rectangle {x0, y0, x1, y1} (x1, y1 exclusive) or null.
export function paintSegment(mask, width, height, a, b, radius, value) {
  const x0 = Math.max(0, Math.floor(Math.min(a.x, b.x) - radius));
  const y0 = Math.max(0, Math.floor(Math.min(a.y, b.y) - radius));
  const x1 = Math.min(width, Math.ceil(Math.max(a.x, b.x) + radius) + 1);
  const y1 = Math.min(height, Math.ceil(Math.max(a.y, b.y) + radius) + 1);
  if (x0 >= x1 || y0 >= y1) return null;
  const dx = b.x - a.x;
  const dy = b.y - a.y;
  const dd = dx * dx + dy * dy;
  const r2 = radius * radius;
  for (let y = y0; y < y1; y++) {
    const py = y - a.y;
    for (let x = x0; x < x1; x++) {
      const px = x - a.x;
      const t = dd > 0 ? Math.min(1, Math.max(0, (px * dx + py * dy) / dd)) : 0;
      const ex = px - t * dx;
      const ey = py - t * dy;
      if (ex * ex + ey * ey <= r2) mask[y * width + x] = value;
    }
  }
  return { x0, y0, x1, y1 };
}

// Paint a polyline (one point paints a disk); returns the touched rectangle or null.
export function paintPolyline(mask, width, height, points, radius, value) {
  if (points.length === 0) return null;
  if (points.length === 1) return paintSegment(mask, width, height, points[0], points[0], radius, value);
  let rect = null;
  for (let i = 0; i + 1 < points.length; i++) {
    rect = unionRect(rect, paintSegment(mask, width, height, points[i], points[i + 1], radius, value));
  }
  return rect;
}

export function unionRect(a, b) {
  if (!a) return b;
  if (!b) return a;
  return { x0: Math.min(a.x0, b.x0), y0: Math.min(a.y0, b.y0), x1: Math.max(a.x1, b.x1), y1: Math.max(a.y1, b.y1) };
}

// The smallest [x0, y0, x1, y1) holding every set pixel, or null for an empty mask.
export function boundingBox(mask, width, height) {
  let x0 = width;
  let y0 = height;
  let x1 = -1;
  let y1 = -1;
  for (let y = 0; y < height; y++) {
    const row = y * width;
    for (let x = 0; x < width; x++) {
      if (mask[row + x]) {
        if (x < x0) x0 = x;
        if (x > x1) x1 = x;
        if (y < y0) y0 = y;
        y1 = y;
      }
    }
  }
  return x1 < 0 ? null : [x0, y0, x1 + 1, y1 + 1];
}

export function countSet(mask) {
  let n = 0;
  for (let i = 0; i < mask.length; i++) n += mask[i];
  return n;
}

// Fill a closed polygon (engine coordinates: pixel centres at integers) into
// a mask: the pixels whose centre is inside it (even-odd), and those within
// half a pixel of its edges, so a polygon around a thin object never comes
// out empty. Returns the touched rectangle or null.
export function fillPolygon(mask, width, height, points, value) {
  if (points.length < 3) return null;
  const ys = points.map((p) => p.y);
  const top = Math.max(0, Math.ceil(Math.min(...ys)));
  const bottom = Math.min(height - 1, Math.floor(Math.max(...ys)));
  for (let y = top; y <= bottom; y++) {
    const xs = [];
    for (let i = 0; i < points.length; i++) {
      const a = points[i];
      const b = points[(i + 1) % points.length];
      if ((a.y <= y && y < b.y) || (b.y <= y && y < a.y)) xs.push(a.x + ((y - a.y) * (b.x - a.x)) / (b.y - a.y));
    }
    xs.sort((p, q) => p - q);
    for (let k = 0; k + 1 < xs.length; k += 2) {
      const x0 = Math.max(0, Math.ceil(xs[k]));
      const x1 = Math.min(width - 1, Math.floor(xs[k + 1]));
      for (let x = x0; x <= x1; x++) mask[y * width + x] = value;
    }
  }
  return paintPolyline(mask, width, height, [...points, points[0]], 0.5, value);
}
