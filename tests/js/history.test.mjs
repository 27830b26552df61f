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

test("a packed history reads back with its shared states shared again", () => {
  const h = new History(10);
  const s0 = { n: 0 };
  const s1 = { n: 1 };
  const s2 = { n: 2 };
  h.push({ before: s0, after: s1, op: null });
  h.push({ before: s1, after: s2, op: { kind: "box", key: "a", params: { box: [1, 2, 3, 4] } } });
  h.undo();
  const data = JSON.parse(JSON.stringify(h.pack((s) => ({ m: s.n }))));
  assert.equal(data.states.length, 3); // s1 once, though two entries hold it
  const back = History.unpack(data, { fromData: (d) => ({ n: d.m }) });
  assert.equal(back.done.length, 1);
  assert.equal(back.undone.length, 1);
  assert.equal(back.latest.n, 1);
  assert.equal(back.done[0].after, back.undone[0].before); // the same object again
  assert.deepEqual(back.redo().op, { kind: "box", key: "a", params: { box: [1, 2, 3, 4] } });
  assert.equal(back.latest.n, 2);
});

test("unpack refuses what is not a history, and keeps only the limit", () => {
  assert.throws(() => History.unpack({ states: [], done: [[0, 1, null]], undone: [] }), /state 0/);
  assert.throws(() => History.unpack(null), /not a packed history/);
  const h = new History(50);
  for (let i = 0; i < 20; i++) h.push({ before: { i }, after: { i: i + 1 }, op: null });
  const back = History.unpack(h.pack(), { limit: 5 });
  assert.equal(back.done.length, 5);
  assert.equal(back.latest.i, 20);
  back.trim(2);
  assert.equal(back.done.length, 2);
  assert.equal(back.undo().after.i, 20);
});
