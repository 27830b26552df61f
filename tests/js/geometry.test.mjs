import assert from "node:assert/strict";
import { test } from "node:test";

import { MAX_SCALE, MIN_SCALE, boxCursor, boxHit, dragBox, editBox, fit, pan, recentre, toImage, toPixel, toScreen, wheelFactor, zoomAt } from "../../static/js/geometry.js";

const close = (a, b, eps = 1e-9) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);

test("fit centres the whole image with a margin", () => {
  const view = fit(1000, 500, 1280, 960, 10);
  close(view.scale, 480 / 960);
  close(view.ty, 10);
  close(view.tx, (1000 - 640) / 2);
  const corner = toScreen(view, 1280, 960);
  close(corner.x, view.tx + 640);
  close(corner.y, 490);
});

test("screen and image coordinates invert each other", () => {
  const view = { scale: 2.5, tx: -30, ty: 12 };
  const p = toImage(view, 100, 200);
  const back = toScreen(view, p.x, p.y);
  close(back.x, 100);
  close(back.y, 200);
  assert.deepEqual(toPixel({ x: 10.5, y: 3.5 }), { x: 10, y: 3 });
});

test("zooming keeps the point under the cursor in place", () => {
  const view = { scale: 1, tx: 5, ty: 7 };
  const before = toImage(view, 321, 123);
  const zoomed = zoomAt(view, 3, 321, 123);
  close(zoomed.scale, 3);
  const after = toImage(zoomed, 321, 123);
  close(after.x, before.x);
  close(after.y, before.y);
  assert.equal(zoomAt(view, 1e9, 0, 0).scale, MAX_SCALE);
  assert.equal(zoomAt(view, 1e-9, 0, 0).scale, MIN_SCALE);
});

test("pan moves by screen pixels", () => {
  assert.deepEqual(pan({ scale: 2, tx: 1, ty: 2 }, 10, -5), { scale: 2, tx: 11, ty: -3 });
});

test("wheel zooms in for negative deltas, symmetric", () => {
  assert.ok(wheelFactor(-100) > 1);
  close(wheelFactor(100) * wheelFactor(-100), 1);
  close(wheelFactor(3, 1), wheelFactor(99));
});

test("a dragged box becomes clipped pixel bounds", () => {
  assert.deepEqual(dragBox({ x: 10.2, y: 5.7 }, { x: 3.9, y: 20.1 }, 100, 50), [3, 5, 11, 21]);
  assert.deepEqual(dragBox({ x: -20, y: -20 }, { x: 500, y: 30 }, 100, 50), [0, 0, 100, 30]);
  assert.equal(dragBox({ x: 5, y: 5 }, { x: 5.5, y: 40 }, 100, 50), null);
  assert.equal(dragBox({ x: -20, y: -20 }, { x: -5, y: -5 }, 100, 50), null);
});

test("recentring after a resize keeps the centre's image point at the centre", () => {
  const view = { scale: 2, tx: 10, ty: -40 };
  const before = toImage(view, 400, 300);
  const after = recentre(view, 800, 600, 800, 540); // a banner took 60 px
  const p = toImage(after, 400, 270);
  close(p.x, before.x);
  close(p.y, before.y);
  assert.equal(after.scale, 2);
});

test("a box's corners, edges and inside are grabbed within a few screen pixels", () => {
  const view = { scale: 2, tx: 0, ty: 0 };
  const box = [10, 10, 60, 40]; // screen (20, 20) - (120, 80)
  assert.equal(boxHit(view, box, 21, 19), "nw");
  assert.equal(boxHit(view, box, 119, 82), "se");
  assert.equal(boxHit(view, box, 70, 20), "n");
  assert.equal(boxHit(view, box, 124, 50), "e");
  assert.equal(boxHit(view, box, 70, 50), "move");
  assert.equal(boxHit(view, box, 140, 50), null);
  assert.equal(boxCursor("ne"), "nesw-resize");
  assert.equal(boxCursor(null), "");
});

test("editing a box moves or resizes it in whole pixels, inside the image, never below 2 px", () => {
  assert.deepEqual(editBox([10, 10, 60, 40], "move", 5.4, -3.6, 100, 80), [15, 6, 65, 36]);
  assert.deepEqual(editBox([10, 10, 60, 40], "move", 100, 100, 100, 80), [50, 50, 100, 80]); // stops at the edge
  assert.deepEqual(editBox([10, 10, 60, 40], "se", 10, 100, 100, 80), [10, 10, 70, 80]);
  assert.deepEqual(editBox([10, 10, 60, 40], "w", 80, 0, 100, 80), [58, 10, 60, 40]);
  assert.deepEqual(editBox([10, 10, 60, 40], "n", 0, -30, 100, 80), [10, 0, 60, 40]);
});
