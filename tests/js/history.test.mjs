import assert from "node:assert/strict";
import { test } from "node:test";

import { History } from "../../static/js/history.js";

test("undo and redo walk the entries in order", () => {
  const h = new History();
  assert.equal(h.undo(), null);
  h.push("a");
  h.push("b");
  assert.ok(h.canUndo && !h.canRedo);
  assert.equal(h.undo(), "b");
  assert.equal(h.undo(), "a");
  assert.equal(h.undo(), null);
  assert.equal(h.redo(), "a");
  assert.equal(h.redo(), "b");
  assert.equal(h.redo(), null);
});

test("a new change forgets what could be redone", () => {
  const h = new History();
  h.push(1);
  h.push(2);
  h.undo();
  h.push(3);
  assert.ok(!h.canRedo);
  assert.equal(h.undo(), 3);
  assert.equal(h.undo(), 1);
});

test("the oldest entries fall off past the limit", () => {
  const h = new History(2);
  for (const e of [1, 2, 3]) h.push(e);
  assert.equal(h.undo(), 3);
  assert.equal(h.undo(), 2);
  assert.equal(h.undo(), null);
  h.clear();
  assert.ok(!h.canUndo && !h.canRedo);
  assert.throws(() => new History(0), /limit/);
});
