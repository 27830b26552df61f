// Pure helpers of the Scores page (no DOM): the rows a figure download draws.

/**
 * The same URL with its `plot` parameters replaced by `rows` and `plotted=1`,
 * so the server draws exactly those rows (none when `rows` is empty).
 * @param {string} href - An absolute or root-relative URL.
 * @param {string[]} rows - Row keys, e.g. ["run:3", "baseline:aop"].
 * @returns {string} The URL, root-relative when `href` was.
 */
export function withPlotRows(href, rows) {
  const url = new URL(href, "http://placeholder.invalid");
  url.searchParams.delete("plot");
  url.searchParams.set("plotted", "1");
  for (const row of rows) url.searchParams.append("plot", row);
  return href.startsWith("/") ? url.pathname + url.search + url.hash : url.toString();
}

/**
 * The label of a seed group's toggle.
 * @param {boolean} open - Whether its runs are shown.
 * @param {number} count - How many runs.
 * @returns {string}
 */
export function seedsLabel(open, count) {
  return `${open ? "hide" : "show"} ${count} seeds`;
}
