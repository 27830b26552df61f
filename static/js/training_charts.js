// The Training pages' charts: a run's losses and held-out MF per epoch
// (run page), and selected runs compared on one chart (index page). Both
// poll GET /training/history for rows after the last one seen while a
// charted run is queued or running.
import { api } from "./api.js";
import { lineChart, render } from "./chart.js";
import { compareChart, foldChoices, History, MEAN, METRICS, runCharts } from "./training_history.js";

const POLL_MS = 3000;

// Every page of rows after history.after (the server sends at most a bounded page each time).
async function load(url, runIds, history) {
  for (let pages = 0; pages < 50; pages += 1) {
    const data = await api("GET", `${url}?runs=${runIds.join(",")}&after=${history.after}`);
    history.merge(data);
    if (!data.more) break;
  }
  return history;
}

function legend(list, series) {
  list.replaceChildren(
    ...series.map((s) => {
      const item = document.createElement("li");
      const swatch = document.createElement("span");
      swatch.className = `swatch series-${s.colour % 10}${s.dashed ? " dashed" : ""}`;
      item.append(swatch, document.createTextNode(s.label));
      return item;
    }),
  );
}

function draw(box, chart, options) {
  const svg = box.querySelector("svg");
  const drawn = chart.series.some((s) => s.points.length);
  box.querySelector(".chart-empty").hidden = drawn;
  svg.classList.toggle("hidden", !drawn);
  // Drawn at the box's own width, so text keeps its size whatever the layout.
  const width = Math.max(320, Math.round(box.clientWidth - 24));
  render(svg, lineChart({ ...chart, width, height: 240, ...options }));
  legend(box.querySelector(".legend"), chart.series.filter((s) => s.points.length));
}

function keepPolling(history, step) {
  if (history.active) setTimeout(step, POLL_MS);
}

// The run page: #run-chart holds #chart-loss and, but for a depth run, #chart-mf; data-loss-label names the loss.
export function runPage(section) {
  const runId = Number(section.dataset.run);
  const history = new History();
  const step = async () => {
    try {
      await load(section.dataset.historyUrl, [runId], history);
      const charts = runCharts(history, runId);
      draw(section.querySelector("#chart-loss"), charts.loss, { xLabel: "epoch", yLabel: section.dataset.lossLabel || "cross-entropy" });
      const mf = section.querySelector("#chart-mf"); // a depth run has no MF chart
      if (mf) draw(mf, charts.mf, { xLabel: "epoch", yLabel: "held-out MF", yMin: 0, yMax: 1 });
      section.dataset.loaded = String(history.rows.size);
    } catch (error) {
      console.warn("training history:", error.message);
    }
    keepPolling(history, step);
  };
  step();
}

// The index page: tick runs in the table (input.compare-run) to chart them together.
export function comparePage(section, table) {
  const metric = section.querySelector("#compare-metric");
  const fold = section.querySelector("#compare-fold");
  let history = new History();
  let timer = null;
  let generation = 0;

  const most = Number(section.dataset.maxRuns || 12);
  const chosen = () => [...table.querySelectorAll("input.compare-run:checked")].map((box) => Number(box.value)).slice(0, most);

  const fillFolds = (runIds) => {
    const keep = fold.value || MEAN;
    const options = [[MEAN, "mean over folds"], ...foldChoices(history, runIds).map((f) => [f, f])];
    fold.replaceChildren(...options.map(([value, text]) => new Option(text, value, false, value === keep)));
    if (![...fold.options].some((o) => o.selected)) fold.value = MEAN;
  };

  const redraw = () => {
    const runIds = chosen();
    fillFolds(runIds);
    const chart = compareChart(history, runIds, metric.value, fold.value || MEAN);
    const bounded = metric.value === "max_f" ? { yMin: 0, yMax: 1 } : {};
    draw(section.querySelector("#chart-compare"), chart, { xLabel: "epoch", yLabel: METRICS[metric.value], ...bounded });
    section.dataset.loaded = String(history.rows.size);
  };

  const refresh = async (fresh) => {
    clearTimeout(timer);
    const mine = (generation += fresh ? 1 : 0);
    if (fresh) history = new History();
    const runIds = chosen();
    const url = new URL(window.location.href);
    if (runIds.length) url.searchParams.set("compare", runIds.join(","));
    else url.searchParams.delete("compare");
    window.history.replaceState(null, "", url);
    try {
      if (runIds.length) await load(section.dataset.historyUrl, runIds, history);
    } catch (error) {
      console.warn("training history:", error.message);
    }
    if (mine !== generation) return; // the choice changed while this request was out
    redraw();
    if (history.active) timer = setTimeout(() => refresh(false), POLL_MS);
  };

  table.addEventListener("change", (event) => {
    if (event.target.matches("input.compare-run")) refresh(true);
  });
  metric.addEventListener("change", redraw);
  fold.addEventListener("change", redraw);
  refresh(true);
}
