import assert from "node:assert/strict";
import { test } from "node:test";

import { fitRect, formatClock, toDisplay, toNative } from "../../static/js/trial_geometry.js";

test("fitRect letterboxes a 4:3 frame in a wide box and scales it", () => {
  assert.deepEqual(fitRect(1280, 960, 1000, 600), { left: 100, top: 0, width: 800, height: 600, scale: 0.625 });
  assert.deepEqual(fitRect(640, 480, 640, 1000), { left: 0, top: 260, width: 640, height: 480, scale: 1 });
  assert.equal(fitRect(100, 50, 0, 0).width, 0);
  assert.throws(() => fitRect(0, 10, 100, 100), RangeError);
});

test("window points map to native pixels with pixel centres at integers", () => {
  // A 4x2 frame drawn 400x200 at (100, 50): each native pixel is 100 display pixels.
  const rect = { left: 100, top: 50, width: 400, height: 200 };
  assert.deepEqual(toNative(150, 100, rect, 4, 2), { x: 0, y: 0 }); // centre of pixel (0, 0)
  assert.deepEqual(toNative(100, 50, rect, 4, 2), { x: -0.5, y: -0.5 }); // its top-left corner
  assert.deepEqual(toNative(500, 250, rect, 4, 2), { x: 3.5, y: 1.5 }); // the frame's bottom-right corner
  assert.deepEqual(toNative(450, 200, rect, 4, 2), { x: 3, y: 1 });
  assert.equal(toNative(99, 100, rect, 4, 2), null);
  assert.equal(toNative(300, 251, rect, 4, 2), null);
});

test("toDisplay inverts toNative at any scale", () => {
  const rect = fitRect(1280, 960, 1117, 731);
  const box = { left: 13 + rect.left, top: 7 + rect.top, width: rect.width, height: rect.height };
  for (const [x, y] of [[0, 0], [639.5, 479.5], [1279.5, 959.5], [-0.5, 12.25]]) {
    const p = toDisplay(x, y, box, 1280, 960);
    const back = toNative(box.left + p.left, box.top + p.top, box, 1280, 960);
    assert.ok(Math.abs(back.x - x) < 1e-9 && Math.abs(back.y - y) < 1e-9, `${x},${y} -> ${back.x},${back.y}`);
  }
});

test("formatClock rounds up and never goes negative", () => {
  assert.equal(formatClock(3600), "60:00");
  assert.equal(formatClock(61.2), "1:02");
  assert.equal(formatClock(0.01), "0:01");
  assert.equal(formatClock(0), "0:00");
  assert.equal(formatClock(-5), "0:00");
});
