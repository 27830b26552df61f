// The epoch history of training runs as the charts need it (pure: tested by
// Node's runner). Rows arrive from GET /training/history in pages; a row
// written again arrives again with a newer id and replaces the old one.

export const METRICS = {
  max_f: "held-out MF",
  loss: "held-out loss",
  train_loss: "training loss",
};
export const MEAN = "__mean__";

export class History {
  constructor() {
    this.after = 0;
    this.runs = new Map(); // id -> the server's summary {id, name, status, active, folds}
    this.rows = new Map(); // "run|fold|epoch" -> row
  }

  // Take one response of /training/history. Runs it no longer lists (deleted) are dropped.
  merge(data) {
    const listed = new Set(data.runs.map((run) => run.id));
    for (const id of [...this.runs.keys()]) if (!listed.has(id)) this.runs.delete(id);
    for (const run of data.runs) this.runs.set(run.id, run);
    for (const row of data.epochs) this.rows.set(`${row.run}|${row.fold}|${row.epoch}`, row);
    for (const [key, row] of this.rows) if (!listed.has(row.run)) this.rows.delete(key);
    this.after = Math.max(this.after, data.after || 0);
    return this;
  }

  get active() {
    return [...this.runs.values()].some((run) => run.active);
  }

  // Fold names of a run in the order their first epoch arrived.
  folds(runId) {
    const folds = [];
    for (const row of [...this.rows.values()].sort((a, b) => a.id - b.id)) {
      if (row.run === runId && !folds.includes(row.fold)) folds.push(row.fold);
    }
    return folds;
  }

  // [{x: epoch, y}] of one fold's metric, by epoch (epochs without the metric left out).
  points(runId, fold, metric) {
    return [...this.rows.values()]
      .filter((row) => row.run === runId && row.fold === fold && Number.isFinite(row[metric]))
      .sort((a, b) => a.epoch - b.epoch)
      .map((row) => ({ x: row.epoch, y: row[metric] }));
  }

  // The mean over the run's folds at each epoch, over the folds that reached it (the note says how many).
  meanPoints(runId, metric) {
    const folds = this.folds(runId);
    const byEpoch = new Map();
    for (const fold of folds) {
      for (const p of this.points(runId, fold, metric)) {
        const list = byEpoch.get(p.x) || [];
        list.push(p.y);
        byEpoch.set(p.x, list);
      }
    }
    return [...byEpoch.entries()]
      .sort((a, b) => a[0] - b[0])
      .map(([x, ys]) => ({ x, y: ys.reduce((s, v) => s + v, 0) / ys.length, note: `mean of ${ys.length} of ${folds.length} folds` }));
  }
}

// A run's two charts: losses (training solid, held-out dashed) and held-out MF,
// one colour per fold, with each fold's action-object prior as a dotted line.
export function runCharts(history, runId) {
  const run = history.runs.get(runId);
  const folds = history.folds(runId);
  const loss = [];
  const mf = [];
  const refs = [];
  folds.forEach((fold, i) => {
    loss.push({ label: `${fold} training`, colour: i, dashed: false, points: history.points(runId, fold, "train_loss") });
    loss.push({ label: `${fold} held-out`, colour: i, dashed: true, points: history.points(runId, fold, "loss") });
    mf.push({ label: fold, colour: i, dashed: false, points: history.points(runId, fold, "max_f") });
    const aop = run?.folds?.[fold]?.aop_max_f;
    if (Number.isFinite(aop)) refs.push({ y: aop, label: `${fold} action-object prior`, colour: i });
  });
  return { loss: { series: loss }, mf: { series: mf, refs }, folds };
}

// Every fold name among some runs (for the comparison's fold choice).
export function foldChoices(history, runIds) {
  const folds = [];
  for (const id of runIds) for (const fold of history.folds(id)) if (!folds.includes(fold)) folds.push(fold);
  return folds;
}

// One line per run: one fold's metric, or the mean over folds; the prior of the same choice as a dotted line.
export function compareChart(history, runIds, metric, fold) {
  const series = [];
  const refs = [];
  runIds.forEach((id, i) => {
    const run = history.runs.get(id);
    if (!run) return;
    const label = `#${id} ${run.name}`;
    if (fold === MEAN) {
      series.push({ label, colour: i, dashed: false, points: history.meanPoints(id, metric) });
    } else if (history.folds(id).includes(fold)) {
      series.push({ label: `${label} (${fold})`, colour: i, dashed: false, points: history.points(id, fold, metric) });
    }
    if (metric !== "max_f") return;
    const aops = Object.entries(run.folds || {})
      .filter(([name, f]) => (fold === MEAN || name === fold) && Number.isFinite(f.aop_max_f))
      .map(([, f]) => f.aop_max_f);
    if (aops.length) refs.push({ y: aops.reduce((s, v) => s + v, 0) / aops.length, label: `${label} action-object prior`, colour: i });
  });
  return { series, refs };
}
