import assert from "node:assert/strict";
import { test } from "node:test";

import { epochTicks, formatTick, lineChart, niceTicks } from "../../static/js/chart.js";
import { compareChart, foldChoices, History, MEAN, runCharts } from "../../static/js/training_history.js";

test("nice ticks cover the range with round steps", () => {
  assert.deepEqual(niceTicks(0, 1, 5), [0, 0.2, 0.4, 0.6, 0.8, 1]);
  assert.deepEqual(niceTicks(0.13, 0.71, 4), [0, 0.2, 0.4, 0.6, 0.8]);
  assert.deepEqual(niceTicks(3, 3, 5).length > 1, true); // a flat series still gets an axis
  assert.deepEqual(niceTicks(NaN, 1), []);
  assert.deepEqual(epochTicks(1), [1]);
  assert.deepEqual(epochTicks(10), [1, 3, 5, 7, 9, 10]);
  assert.equal(formatTick(0.25), "0.25");
  assert.equal(formatTick(2), "2");
});

test("a line chart maps points into the plot and labels every point", () => {
  const tree = lineChart({
    width: 200, height: 100,
    series: [{ label: "cooking", colour: 1, dashed: true, points: [{ x: 1, y: 0 }, { x: 2, y: 1 }] }],
    refs: [{ y: 0.5, label: "prior", colour: 1 }],
    yMin: 0, yMax: 1,
  });
  assert.equal(tree.tag, "svg");
  assert.equal(tree.attrs.viewBox, "0 0 200 100");
  const path = tree.children.find((c) => c.tag === "path");
  // x: epoch 1 at the left margin (52), epoch 2 at the right edge (200 - 14); y: 0 at the bottom (100 - 38), 1 at the top (12).
  assert.equal(path.attrs.d, "M52.0 62.0 L186.0 12.0");
  assert.match(path.attrs.class, /series-1 dashed/);
  const dots = tree.children.filter((c) => c.tag === "circle");
  assert.deepEqual(dots.map((d) => d.children[0].text), ["cooking, epoch 1: 0.0000", "cooking, epoch 2: 1.0000"]);
  const ref = tree.children.find((c) => c.tag === "line" && c.attrs.class.startsWith("ref"));
  assert.equal(ref.attrs.y1, 37);
});

test("a chart without points has axes and no lines", () => {
  const tree = lineChart({ series: [{ label: "x", colour: 0, points: [] }] });
  assert.equal(tree.children.filter((c) => c.tag === "path").length, 0);
  assert.ok(tree.children.some((c) => c.attrs?.class === "axis"));
});

function page(runs, epochs, after) {
  return { runs, epochs, after, more: false };
}

const RUN = (id, folds = {}, active = false) => ({ id, name: `run ${id}`, status: active ? "running" : "done", active, folds });

test("history merges pages, replaces rewritten rows and forgets deleted runs", () => {
  const h = new History();
  h.merge(page([RUN(1, {}, true), RUN(2)], [
    { id: 1, run: 1, fold: "cooking", epoch: 1, train_loss: 0.7, loss: null, max_f: 0.2 },
    { id: 2, run: 2, fold: "single", epoch: 1, train_loss: 0.6, loss: 0.5, max_f: 0.4 },
  ], 2));
  assert.equal(h.after, 2);
  assert.ok(h.active);
  h.merge(page([RUN(1, { cooking: { aop_max_f: 0.3 } }), RUN(2)], [
    { id: 3, run: 1, fold: "cooking", epoch: 2, train_loss: 0.5, loss: 0.45, max_f: 0.35 },
    { id: 4, run: 1, fold: "cooking", epoch: 1, train_loss: 0.69, loss: null, max_f: 0.25 },
    { id: 5, run: 1, fold: "dining", epoch: 1, train_loss: 0.8, loss: null, max_f: 0.1 },
  ], 5));
  assert.ok(!h.active);
  assert.deepEqual(h.points(1, "cooking", "max_f"), [{ x: 1, y: 0.25 }, { x: 2, y: 0.35 }]);
  assert.deepEqual(h.points(1, "cooking", "loss"), [{ x: 2, y: 0.45 }]); // epochs without the metric are left out
  assert.deepEqual(h.folds(1), ["cooking", "dining"]);
  assert.deepEqual(h.meanPoints(1, "max_f"), [
    { x: 1, y: 0.175, note: "mean of 2 of 2 folds" },
    { x: 2, y: 0.35, note: "mean of 1 of 2 folds" },
  ]);
  const charts = runCharts(h, 1);
  assert.deepEqual(charts.loss.series.map((s) => [s.label, s.colour, s.dashed]), [
    ["cooking training", 0, false], ["cooking held-out", 0, true], ["dining training", 1, false], ["dining held-out", 1, true]]);
  assert.deepEqual(charts.mf.refs, [{ y: 0.3, label: "cooking action-object prior", colour: 0 }]);
  assert.deepEqual(foldChoices(h, [1, 2]), ["cooking", "dining", "single"]);
  const cmp = compareChart(h, [1, 2], "max_f", MEAN);
  assert.deepEqual(cmp.series.map((s) => [s.label, s.points.length]), [["#1 run 1", 2], ["#2 run 2", 1]]);
  assert.deepEqual(compareChart(h, [1, 2], "max_f", "single").series.map((s) => s.label), ["#2 run 2 (single)"]);
  // Run 2 deleted: the server no longer lists it.
  h.merge(page([RUN(1)], [], 5));
  assert.deepEqual([...h.runs.keys()], [1]);
  assert.equal(h.points(2, "single", "max_f").length, 0);
});
