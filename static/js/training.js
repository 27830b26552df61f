// Training pages: while a run is queued or running, poll its progress and
// update its row; when one finishes, reload to show its scores and checkpoints.
// The charts (training_charts.js) poll their own data.
import { api } from "./api.js";
import { formatBytes, uploadWeights } from "./weights_upload.js";
import { comparePage, runPage } from "./training_charts.js";

const ACTIVE = new Set(["queued", "running"]);
const POLL_MS = 2000;

export function formatDuration(seconds) {
  if (seconds === null || seconds === undefined) return "–";
  const s = Math.round(seconds);
  if (s >= 3600) return `${Math.floor(s / 3600)} h ${String(Math.floor((s % 3600) / 60)).padStart(2, "0")} min`;
  if (s >= 60) return `${Math.floor(s / 60)} min ${String(s % 60).padStart(2, "0")} s`;
  return `${s} s`;
}

function render(row, run) {
  const field = (name) => row.querySelector(`[data-field="${name}"]`);
  row.dataset.status = run.status;
  field("status").textContent = run.status;
  field("status").className = `status status-${run.status}`;
  field("bar").value = run.progress;
  field("percent").textContent = `${Math.round(run.progress * 100)}%`;
  field("loss").textContent = run.loss === null ? "–" : run.loss.toFixed(4);
  field("eta").textContent = run.status === "running" ? formatDuration(run.eta_s) : "–";
  field("message").textContent = run.message || "";
}

async function poll(table) {
  const rows = [...table.querySelectorAll("tr[data-run]")];
  const active = rows.filter((row) => ACTIVE.has(row.dataset.status));
  if (!active.length) return;
  let finished = false;
  try {
    const ids = active.map((row) => row.dataset.run).join(",");
    const data = await api("GET", `${table.dataset.statusUrl}?ids=${ids}`);
    for (const run of data.runs) {
      const row = table.querySelector(`tr[data-run="${run.id}"]`);
      if (!row) continue;
      render(row, run);
      if (!ACTIVE.has(run.status)) finished = true;
    }
  } catch (error) {
    console.warn("training progress:", error.message);
  }
  // Scores and checkpoints appear with a reload, unless the start form is being filled in.
  if (finished && !document.querySelector("#start-run[open]")) {
    window.location.reload();
    return;
  }
  setTimeout(() => poll(table), POLL_MS);
}

// The released-weights form: upload in chunks with a progress bar, then show the new run.
function wireWeightsForm(form) {
  const bar = document.getElementById("weights-progress");
  const status = document.getElementById("weights-status");
  const button = form.querySelector("button[type=submit]");
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    const file = form.elements.file.files[0];
    if (!file) {
      status.textContent = "Choose a .caffemodel file first.";
      return;
    }
    button.disabled = true;
    bar.hidden = false;
    bar.value = 0;
    try {
      const answer = await uploadWeights(file, {
        base: form.dataset.startUrl.replace(/\/uploads$/, ""),
        name: form.elements.name.value.trim() || null,
        width: Number(form.elements.width.value),
        height: Number(form.elements.height.value),
        onProgress: (sent, total) => {
          bar.value = sent / total;
          status.textContent = `Sending ${formatBytes(sent, total)}…`;
        },
      });
      status.textContent = answer.message;
      setTimeout(() => window.location.reload(), 1500);
    } catch (error) {
      status.textContent = `Not imported: ${error.message}`;
      bar.hidden = true;
      button.disabled = false;
    }
  });
}

if (typeof document !== "undefined") {
  const table = document.getElementById("runs");
  if (table) setTimeout(() => poll(table), POLL_MS);
  const weights = document.getElementById("weights-form");
  if (weights) wireWeightsForm(weights);
  const runChart = document.getElementById("run-chart");
  if (runChart) runPage(runChart);
  const compare = document.getElementById("compare");
  if (compare && table) comparePage(compare, table);
}
