import assert from "node:assert/strict";
import { test } from "node:test";

import { scaleTicks, formatTick } from "../../static/js/heat_scale.js";
import { maskFromRGBA, outlineBand, paintBand, placeTag, tagText, thicknessFor } from "../../static/js/outline.js";
import { formatBytes, progressText } from "../../static/js/export.js";

function grid(rows) {
  const width = rows[0].length;
  return { width, height: rows.length, mask: Uint8Array.from(rows.join(""), (c) => Number(c)) };
}

function rows(mask, width) {
  const out = [];
  for (let i = 0; i < mask.length; i += width) out.push(Array.from(mask.slice(i, i + width)).join(""));
  return out;
}

test("a band of thickness 1 is the 8-connected boundary; the picture's edge counts as outside", () => {
  const { mask, width, height } = grid(["000000", "011110", "011110", "011110", "011110", "000000"]);
  assert.deepEqual(rows(outlineBand(mask, width, height, 1), width), ["000000", "011110", "010010", "010010", "011110", "000000"]);
  const full = new Uint8Array(16).fill(1);
  assert.deepEqual(rows(outlineBand(full, 4, 4, 1), 4), ["1111", "1001", "1001", "1111"]);
});

test("a thicker band eats further in, and a small object becomes all band", () => {
  const full = new Uint8Array(49).fill(1);
  assert.deepEqual(rows(outlineBand(full, 7, 7, 2), 7), ["1111111", "1111111", "1100011", "1100011", "1100011", "1111111", "1111111"]);
  const { mask, width, height } = grid(["0000", "0110", "0110", "0000"]);
  assert.deepEqual(outlineBand(mask, width, height, 3), mask);
  assert.equal(outlineBand(new Uint8Array(9), 3, 3, 2).reduce((a, b) => a + b), 0);
});

test("the band matches a brute-force erosion on a random mask", () => {
  const width = 23;
  const height = 17;
  let seed = 7;
  const mask = Uint8Array.from({ length: width * height }, () => ((seed = (seed * 1103515245 + 12345) % 2 ** 31) % 3 ? 1 : 0));
  for (const r of [1, 2, 4]) {
    const band = outlineBand(mask, width, height, r);
    for (let y = 0; y < height; y++) {
      for (let x = 0; x < width; x++) {
        let kept = mask[y * width + x] === 1;
        for (let dy = -r; dy <= r && kept; dy++) {
          for (let dx = -r; dx <= r && kept; dx++) {
            const xx = x + dx;
            const yy = y + dy;
            kept = xx >= 0 && yy >= 0 && xx < width && yy < height && mask[yy * width + xx] === 1;
          }
        }
        assert.equal(band[y * width + x], mask[y * width + x] && !kept ? 1 : 0, `r=${r} (${x}, ${y})`);
      }
    }
  }
});

test("masks come from a PNG's red channel; bands paint opaque colour", () => {
  const rgba = Uint8ClampedArray.from([255, 255, 255, 255, 0, 0, 0, 255, 200, 0, 0, 255]);
  assert.deepEqual(Array.from(maskFromRGBA(rgba, 3, 1)), [1, 0, 1]);
  const data = new Uint8ClampedArray(12);
  paintBand(data, Uint8Array.from([0, 1, 0]), [10, 20, 30]);
  assert.deepEqual(Array.from(data), [0, 0, 0, 0, 10, 20, 30, 255, 0, 0, 0, 0]);
});

test("outlines keep about 2 screen pixels whatever the zoom; tags name the object and its kind", () => {
  assert.equal(thicknessFor(1280, 400), 6);
  assert.equal(thicknessFor(320, 400), 2);
  assert.equal(thicknessFor(64, 400), 1);
  assert.equal(thicknessFor(640, 0), 2);
  assert.equal(tagText(2, "tactile"), "2 tactile");
  assert.equal(tagText(1, null), "1");
});

test("the colour bar's ticks: the probability scale, or one map's range", () => {
  assert.deepEqual(scaleTicks(0, 1), ["0", "0.25", "0.5", "0.75", "1"]);
  assert.deepEqual(scaleTicks(0.02, 0.08), ["0.02", "0.035", "0.05", "0.065", "0.08"]);
  assert.equal(formatTick(0.0123456), "0.0123");
  assert.equal(formatTick(1 / 3), "0.333");
});

test("an export's progress line", () => {
  assert.equal(progressText({ status: "running", done: 3, total: 10 }), "3 of 10 frames");
  assert.equal(
    progressText({ status: "done", done: 10, total: 10, annotations: 12, instances: 15, size_bytes: 2_345_678 }),
    "10 of 10 frames: 12 annotations, 15 action-objects, 2.3 MB",
  );
  assert.equal(
    progressText({ status: "done", done: 1, total: 1, annotations: 1, instances: 1, size_bytes: 1500 }),
    "1 of 1 frame: 1 annotation, 1 action-object, 1.5 kB",
  );
  assert.equal(formatBytes(999), "999 Bytes");
});

test("tags sit above their box, inside it when that place is taken or off the picture", () => {
  const placed = [];
  assert.deepEqual(placeTag([10, 30, 60, 80], 20, 10, 100, 100, placed), { x: 10, y: 20 });
  assert.deepEqual(placeTag([15, 32, 50, 70], 20, 10, 100, 100, placed), { x: 15, y: 32 }); // above is taken
  assert.deepEqual(placeTag([0, 0, 40, 40], 20, 10, 100, 100, []), { x: 0, y: 0 }); // at the top: inside
  assert.deepEqual(placeTag([95, 50, 100, 60], 20, 10, 100, 100, []), { x: 80, y: 40 }); // kept in the picture
  assert.equal(placed.length, 2);
});
