import assert from "node:assert/strict";
import { test } from "node:test";

import { ClickList, keyAction } from "../../static/js/trial_input.js";

test("several clicks with undo", () => {
  const clicks = new ClickList({ multiple: true, max: 3 });
  assert.ok(clicks.add(1, 2, 300));
  assert.ok(clicks.add(3, 4, 500));
  assert.deepEqual(clicks.undo(), { x: 3, y: 4, rt_ms: 500 });
  assert.ok(clicks.add(5, 6, 900));
  assert.ok(clicks.add(7, 8, 950));
  assert.equal(clicks.add(9, 9, 990), false); // the maximum
  assert.deepEqual(JSON.parse(JSON.stringify(clicks)), [
    { x: 1, y: 2, rt_ms: 300 },
    { x: 5, y: 6, rt_ms: 900 },
    { x: 7, y: 8, rt_ms: 950 },
  ]);
  clicks.undo();
  clicks.undo();
  clicks.undo();
  assert.equal(clicks.undo(), undefined);
  assert.equal(clicks.length, 0);
});

test("one click only when several are not allowed", () => {
  const clicks = new ClickList({ multiple: false });
  assert.ok(clicks.add(1, 1, 10));
  assert.equal(clicks.add(2, 2, 20), false);
  assert.equal(clicks.length, 1);
});

test("keyboard shortcuts", () => {
  assert.equal(keyAction("Enter", { multiple: true }), "next");
  assert.equal(keyAction("Enter", { multiple: false }), null);
  assert.equal(keyAction("n", { multiple: false }), "none");
  assert.equal(keyAction("N", { multiple: true }), "none");
  assert.equal(keyAction("Backspace", { multiple: true }), "undo");
  assert.equal(keyAction("x", { multiple: true }), null);
});
