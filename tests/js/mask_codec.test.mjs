import assert from "node:assert/strict";
import { test } from "node:test";

import {
  columnCounts,
  countsToString,
  decodeCocoRle,
  decodeRuns,
  encodeCocoRle,
  encodeRuns,
  maskFromRGBA,
  stringToCounts,
} from "../../static/js/mask_codec.js";

function randomMask(width, height, seed) {
  // A few rectangles from a small deterministic generator.
  let s = seed;
  const rand = (n) => {
    s = (s * 1103515245 + 12345) % 2147483648;
    return s % n;
  };
  const mask = new Uint8Array(width * height);
  for (let k = 0; k < 4; k++) {
    const x0 = rand(width);
    const y0 = rand(height);
    const x1 = Math.min(width, x0 + rand(width));
    const y1 = Math.min(height, y0 + rand(height));
    for (let y = y0; y < y1; y++) for (let x = x0; x < x1; x++) mask[y * width + x] = 1;
  }
  return mask;
}

test("pycocotools' own example strings", () => {
  // pycocotools.mask.encode of a 4x5 mask with rows 1-2, columns 2-3 set: b'92203'
  const mask = new Uint8Array(20);
  for (const [y, x] of [[1, 2], [1, 3], [2, 2], [2, 3]]) mask[y * 5 + x] = 1;
  assert.deepEqual(columnCounts(mask, 5, 4), [9, 2, 2, 2, 5]);
  assert.deepEqual(encodeCocoRle(mask, 5, 4), { size: [4, 5], counts: "92203" });
  // Uncompressed [7, 2, 2, 2, 7] compresses to b'72205' (pycocotools.mask.frPyObjects).
  assert.equal(countsToString([7, 2, 2, 2, 7]), "72205");
  assert.deepEqual(stringToCounts("72205"), [7, 2, 2, 2, 7]);
});

test("large and negative differences survive the string form", () => {
  const counts = [0, 5_000_000, 3, 1, 4_999_000, 2 ** 31 + 7, 1];
  assert.deepEqual(stringToCounts(countsToString(counts)), counts);
});

test("COCO RLE round trip on random masks", () => {
  for (let seed = 1; seed < 30; seed++) {
    const [w, h] = [17 + (seed % 5), 11 + (seed % 7)];
    const mask = randomMask(w, h, seed);
    const rle = encodeCocoRle(mask, w, h);
    assert.deepEqual(decodeCocoRle(rle), mask);
    assert.deepEqual(decodeCocoRle({ size: [h, w], counts: columnCounts(mask, w, h) }), mask);
  }
});

test("empty and full masks", () => {
  const empty = new Uint8Array(12);
  assert.deepEqual(encodeCocoRle(empty, 4, 3).counts, countsToString([12]));
  const full = new Uint8Array(12).fill(1);
  assert.deepEqual(columnCounts(full, 4, 3), [0, 12]);
  assert.deepEqual(decodeCocoRle(encodeCocoRle(full, 4, 3)), full);
});

test("bad input is refused", () => {
  assert.throws(() => encodeCocoRle(new Uint8Array(5), 2, 2), /expected 4/);
  assert.throws(() => decodeCocoRle({ size: [2, 2], counts: [1, 1] }), /covers 2 pixels/);
  assert.throws(() => stringToCounts("\u0001"), /alphabet/);
  assert.throws(() => stringToCounts("o"), /ends inside/);
});

test("row runs round trip", () => {
  const mask = randomMask(23, 9, 7);
  const runs = encodeRuns(mask);
  assert.ok(runs instanceof Uint32Array);
  assert.deepEqual(decodeRuns(runs, mask.length), mask);
  assert.deepEqual(Array.from(encodeRuns(Uint8Array.from([1, 1, 0]))), [0, 2, 1]);
  assert.throws(() => decodeRuns(Uint32Array.from([2]), 3), /cover 2/);
});

test("a mask from decoded PNG pixels", () => {
  const rgba = Uint8ClampedArray.from([0, 0, 0, 255, 255, 255, 255, 255, 128, 128, 128, 255]);
  assert.deepEqual(Array.from(maskFromRGBA(rgba, 3)), [0, 1, 1]);
});

test("the same strings as pycocotools.mask.encode", () => {
  // Strings printed by pycocotools 2.0 for these masks.
  const a = new Uint8Array(60 * 80);
  for (let y = 5; y < 50; y++) for (let x = 10; x < 70; x++) a[y * 80 + x] = 1;
  for (let y = 20; y < 30; y++) for (let x = 30; x < 40; x++) a[y * 80 + x] = 0;
  const expectedA = "mb0]1?" + "0".repeat(38) + "ROK55KK55KK55KK55KK55KK55KK55KK55KK55KK55i" + "0".repeat(59) + "cb0";
  assert.equal(encodeCocoRle(a, 80, 60).counts, expectedA);
  assert.deepEqual(decodeCocoRle({ size: [60, 80], counts: expectedA }), a);

  const b = new Uint8Array(40 * 50);
  for (let y = 0; y < 40; y++) for (let x = y; x < y + 5; x++) b[y * 50 + x] = 1;
  const expectedB = "01W11O1O1O1" + "0".repeat(71) + "O1O1O1OY6";
  assert.equal(encodeCocoRle(b, 50, 40).counts, expectedB);
});
