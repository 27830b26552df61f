// Outlines of binary masks, drawn over a picture (the frame viewer).
//
// A mask is a Uint8Array of width * height values, 0 or 1, row by row.

// The mask held by an RGBA ImageData's red channel (a 0/255 PNG drawn on a canvas).
export function maskFromRGBA(data, width, height) {
  const mask = new Uint8Array(width * height);
  for (let i = 0; i < mask.length; i++) mask[i] = data[4 * i] > 127 ? 1 : 0;
  return mask;
}

// Runs of set values along one line (`count` values `step` apart from `start`):
// keep[i] = 1 when the `r` values on each side of i are set too (the picture's
// edge counts as unset), that is, the line eroded by a segment of 2r + 1.
function erodeLine(src, dst, start, step, count, r) {
  let run = 0;
  for (let k = 0; k < count; k++) {
    const i = start + k * step;
    run = src[i] ? run + 1 : 0;
    dst[i] = run > r ? 1 : 0; // the r values before i (and i) are set
  }
  run = 0;
  for (let k = count - 1; k >= 0; k--) {
    const i = start + k * step;
    run = src[i] ? run + 1 : 0;
    if (run <= r) dst[i] = 0; // ... and the r values after it
  }
}

// The inner band of a mask: its pixels within `thickness` pixels (a square
// neighbourhood) of an unset pixel or of the picture's edge. Thickness 1 is
// the 8-connected boundary. O(width * height) whatever the thickness.
export function outlineBand(mask, width, height, thickness) {
  const r = Math.max(1, Math.floor(thickness));
  const across = new Uint8Array(mask.length);
  for (let y = 0; y < height; y++) erodeLine(mask, across, y * width, 1, width, r);
  const inner = new Uint8Array(mask.length);
  for (let x = 0; x < width; x++) erodeLine(across, inner, x, width, height, r);
  const band = new Uint8Array(mask.length);
  for (let i = 0; i < mask.length; i++) band[i] = mask[i] && !inner[i] ? 1 : 0;
  return band;
}

// Paint the band's pixels into RGBA `data` in colour [r, g, b] (opaque).
export function paintBand(data, band, colour) {
  for (let i = 0; i < band.length; i++) {
    if (!band[i]) continue;
    data[4 * i] = colour[0];
    data[4 * i + 1] = colour[1];
    data[4 * i + 2] = colour[2];
    data[4 * i + 3] = 255;
  }
}

// How thick (in the picture's pixels) an outline must be to look `screenPixels` wide when
// a picture `naturalWidth` wide is shown `shownWidth` wide.
export function thicknessFor(naturalWidth, shownWidth, screenPixels = 2) {
  if (!(shownWidth > 0)) return screenPixels;
  return Math.max(1, Math.round((screenPixels * naturalWidth) / shownWidth));
}

// An object's tag: its number in its annotation and its kind ("2 tactile").
export function tagText(number, kind) {
  return kind ? `${number} ${kind}` : `${number}`;
}

// Where an object's tag (w x h) goes: above its box's top-left corner, else
// just inside it, else under or at the bottom of the box — the first place
// that stays in the picture (W x H) and overlaps no tag in `placed`
// ([x, y, w, h] each; the chosen one is added).
export function placeTag(box, w, h, W, H, placed) {
  const [x0, y0, , y1] = box;
  const x = Math.min(Math.max(0, x0), Math.max(0, W - w));
  const clampY = (y) => Math.min(Math.max(0, y), Math.max(0, H - h));
  const candidates = [y0 - h, y0, y1, y1 - h].filter((y) => y >= 0 && y + h <= H).map((y) => [x, y]);
  const free = ([cx, cy]) => placed.every(([px, py, pw, ph]) => cx + w <= px || px + pw <= cx || cy + h <= py || py + ph <= cy);
  const [tx, ty] = candidates.find(free) ?? candidates[0] ?? [x, clampY(y0)];
  placed.push([tx, ty, w, h]);
  return { x: tx, y: ty };
}
