import assert from "node:assert/strict";
import { test } from "node:test";

import { boundingBox, countSet, paintPolyline, paintSegment, unionRect } from "../../static/js/raster.js";

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
