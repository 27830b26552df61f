import assert from "node:assert/strict";
import { test } from "node:test";

import { boundingBox, countSet, fillPolygon, paintPolyline, paintSegment, unionRect } from "../../static/js/raster.js";

function rows(mask, width) {
  const out = [];
  for (let i = 0; i < mask.length; i += width) out.push(Array.from(mask.slice(i, i + width)).join(""));
  return out;
}

test("one point paints a disk (egonet.grabcut.stroke_footprint's example)", () => {
  const mask = new Uint8Array(25);
  const rect = paintPolyline(mask, 5, 5, [{ x: 2, y: 2 }], 1, 1);
  assert.deepEqual(rows(mask, 5), ["00000", "00100", "01110", "00100", "00000"]);
  assert.deepEqual(rect, { x0: 1, y0: 1, x1: 4, y1: 4 });
});

test("a segment covers the pixels within the radius of it, and erases too", () => {
  const mask = new Uint8Array(6 * 4).fill(1);
  paintSegment(mask, 6, 4, { x: 0, y: 1 }, { x: 5, y: 1 }, 0.5, 0);
  assert.deepEqual(rows(mask, 6), ["111111", "000000", "111111", "111111"]);
});

test("strokes outside the mask touch nothing", () => {
  const mask = new Uint8Array(16);
  assert.equal(paintSegment(mask, 4, 4, { x: -10, y: -10 }, { x: -8, y: -9 }, 1, 1), null);
  assert.equal(paintPolyline(mask, 4, 4, [], 3, 1), null);
  assert.equal(countSet(mask), 0);
});

test("a polyline is the union of its segments", () => {
  const mask = new Uint8Array(7 * 7);
  const rect = paintPolyline(mask, 7, 7, [{ x: 1, y: 1 }, { x: 5, y: 1 }, { x: 5, y: 5 }], 0.5, 1);
  assert.deepEqual(rows(mask, 7), ["0000000", "0111110", "0000010", "0000010", "0000010", "0000010", "0000000"]);
  assert.deepEqual(rect, { x0: 0, y0: 0, x1: 7, y1: 7 });
  assert.deepEqual(boundingBox(mask, 7, 7), [1, 1, 6, 6]);
  assert.equal(boundingBox(new Uint8Array(4), 2, 2), null);
});

test("rectangles unite", () => {
  assert.deepEqual(unionRect(null, { x0: 1, y0: 2, x1: 3, y1: 4 }), { x0: 1, y0: 2, x1: 3, y1: 4 });
  assert.deepEqual(unionRect({ x0: 0, y0: 5, x1: 2, y1: 6 }, { x0: 1, y0: 2, x1: 3, y1: 4 }), { x0: 0, y0: 2, x1: 3, y1: 6 });
});

test("a polygon fills the pixels whose centre is inside, and a thin one is never empty", () => {
  const mask = new Uint8Array(8 * 6);
  // A triangle with corners on pixel centres (1, 1), (6, 1), (1, 4): its long side runs
  // x = 6 - 5 (y - 1) / 3, so row 2 is inside up to x = 4.33 and row 3 up to 2.67; (5, 2) and
  // (3, 3) are 0.34 and 0.17 px from that side, so they are taken too.
  const rect = fillPolygon(mask, 8, 6, [{ x: 1, y: 1 }, { x: 6, y: 1 }, { x: 1, y: 4 }], 1);
  assert.deepEqual(rows(mask, 8), ["00000000", "01111110", "01111100", "01110000", "01000000", "00000000"]);
  assert.deepEqual(rect, { x0: 0, y0: 0, x1: 8, y1: 6 });
  // A sliver a tenth of a pixel wide along row 2 still marks the row's pixels it runs over.
  const thin = new Uint8Array(8 * 6);
  fillPolygon(thin, 8, 6, [{ x: 1, y: 2 }, { x: 6, y: 2 }, { x: 6, y: 2.1 }, { x: 1, y: 2.1 }], 1);
  assert.deepEqual(rows(thin, 8)[2], "01111110");
  assert.equal(countSet(thin), 6);
  // Erasing with a polygon; fewer than three corners do nothing.
  fillPolygon(mask, 8, 6, [{ x: 0, y: 0 }, { x: 7, y: 0 }, { x: 7, y: 1.4 }, { x: 0, y: 1.4 }], 0);
  assert.equal(rows(mask, 8)[1], "00000000");
  assert.equal(fillPolygon(mask, 8, 6, [{ x: 0, y: 0 }, { x: 3, y: 3 }], 1), null);
});
