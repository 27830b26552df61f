// The Scores page: the metric and frame switches apply at once, a group of
// seeds opens to show its runs, and the plots' legend picks the rows drawn
// (in every plot and in the SVG/PDF downloads) without reloading.
import { seedsLabel, withPlotRows } from "./scores_links.js";

const choice = document.getElementById("score-choice");
for (const input of choice?.querySelectorAll("fieldset.view input, input[name=answered_only], input[name=exclude_failed_checks], input[name=by_condition]") ?? []) {
  input.addEventListener("change", () => choice.requestSubmit());
}

for (const button of document.querySelectorAll("button.seeds-toggle")) {
  button.addEventListener("click", () => {
    const group = button.dataset.group;
    const open = button.getAttribute("aria-expanded") !== "true";
    const rows = [...document.querySelectorAll("tr.seed-row")].filter((tr) => tr.dataset.group === group);
    for (const tr of rows) tr.hidden = !open;
    // The same group appears in each statistic's table: keep every toggle in step.
    for (const other of document.querySelectorAll("button.seeds-toggle")) {
      if (other.dataset.group !== group) continue;
      other.setAttribute("aria-expanded", String(open));
      other.textContent = seedsLabel(open, Number(other.dataset.count));
    }
  });
}

const legend = document.getElementById("plot-rows");
if (legend) {
  const boxes = [...legend.querySelectorAll("input[name=plot]")];
  const update = () => {
    const chosen = boxes.filter((box) => box.checked).map((box) => box.value);
    for (const line of document.querySelectorAll(".pr-plot g.line")) {
      line.setAttribute("visibility", chosen.includes(line.dataset.row) ? "visible" : "hidden");
    }
    for (const link of document.querySelectorAll("a.figure-link")) {
      link.setAttribute("href", withPlotRows(link.getAttribute("href"), chosen));
    }
  };
  for (const box of boxes) box.addEventListener("change", update);
  legend.querySelector("button.draw").hidden = true;
}
