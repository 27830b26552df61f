import assert from "node:assert/strict";
import { test } from "node:test";

import { seedsLabel, withPlotRows } from "../../static/js/scores_links.js";

test("withPlotRows replaces the plot parameters and keeps the rest", () => {
  const href = "/scores/figure.svg?chosen=1&runs=3&plot=run%3A3&plot=baseline%3Aaop&activity=all";
  const got = new URL(withPlotRows(href, ["participant:7"]), "http://x.invalid");
  assert.equal(got.pathname, "/scores/figure.svg");
  assert.deepEqual(got.searchParams.getAll("plot"), ["participant:7"]);
  assert.equal(got.searchParams.get("plotted"), "1");
  assert.equal(got.searchParams.get("runs"), "3");
  assert.equal(got.searchParams.get("activity"), "all");
  assert.ok(withPlotRows(href, []).startsWith("/scores/figure.svg?"));
  assert.deepEqual(new URL(withPlotRows(href, []), "http://x.invalid").searchParams.getAll("plot"), []);
});

test("withPlotRows keeps an absolute URL absolute", () => {
  assert.equal(withPlotRows("http://h.invalid/a?b=1", ["x"]), "http://h.invalid/a?b=1&plotted=1&plot=x");
});

test("seedsLabel", () => {
  assert.equal(seedsLabel(true, 3), "hide 3 seeds");
  assert.equal(seedsLabel(false, 2), "show 2 seeds");
});
