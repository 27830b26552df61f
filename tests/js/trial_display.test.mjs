import assert from "node:assert/strict";
import { test } from "node:test";

import { displayRect, roundMs, windowProblem } from "../../static/js/trial_display.js";

test("by default the frame is fitted to the stage, centred", () => {
  const r = displayRect(320, 240, 1000, 600);
  assert.deepEqual([r.left, r.top, r.width, r.height, r.fits], [100, 0, 800, 600, true]);
});

test("a fixed width is kept whatever the stage, and says when it does not fit", () => {
  const r = displayRect(320, 240, 1000, 600, { width_px: 640 });
  assert.deepEqual([r.left, r.top, r.width, r.height, r.scale, r.fits], [180, 60, 640, 480, 2, true]);
  const small = displayRect(320, 240, 390, 500, { width_px: 640 });
  assert.equal(small.width, 640);
  assert.equal(small.fits, false);
  assert.match(windowProblem(390, 700, { width_px: 640 }, small), /640 × 480 pixels large/);
});

test("a fraction takes that share of the stage", () => {
  const r = displayRect(320, 240, 1000, 600, { fraction: 0.5 });
  assert.deepEqual([r.left, r.top, r.width, r.height], [300, 150, 400, 300]);
});

test("the minimum window is checked on both sides", () => {
  const min = { min_window: { width: 1024, height: 700 } };
  assert.equal(windowProblem(1280, 800, min), null);
  assert.match(windowProblem(1000, 800, min), /at least 1024 × 700 pixels; yours is 1000 × 800/);
  assert.match(windowProblem(1280, 699.6, min), /yours is 1280 × 700/);
  assert.equal(windowProblem(300, 300, {}), null);
});

test("reaction times lose their float noise", () => {
  assert.equal(roundMs(1234.5999999999767), 1234.6);
  assert.equal(roundMs(0.04), 0);
  assert.equal(String(roundMs(100.30000000000001)), "100.3");
});
