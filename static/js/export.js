// An export's page: while the worker builds it, poll its progress; show the download when it is done.
import { api } from "./api.js";

const ACTIVE = new Set(["queued", "running"]);
const POLL_MS = 1000;

// The progress line of an export's state (pure: tested in tests/js).
export function progressText(state) {
  const frames = `${state.done} of ${count(state.total, "frame")}`;
  if (state.status !== "done") return frames;
  return `${frames}: ${count(state.annotations, "annotation")}, ${count(state.instances, "action-object")}, ${formatBytes(state.size_bytes)}`;
}

const count = (n, noun) => `${n} ${noun}${n === 1 ? "" : "s"}`;

export function formatBytes(bytes) {
  if (!bytes) return "0 Bytes";
  const units = ["Bytes", "kB", "MB", "GB", "TB"];
  const i = Math.min(units.length - 1, Math.floor(Math.log(bytes) / Math.log(1000)));
  return i === 0 ? `${bytes} Bytes` : `${(bytes / 1000 ** i).toFixed(1)} ${units[i]}`;
}

function render(section, state) {
  const $ = (id) => document.getElementById(id);
  section.dataset.status = state.status;
  const badge = $("export-status").querySelector(".status");
  badge.className = `status status-${state.status}`;
  badge.textContent = state.status.replace("_", " ");
  $("export-progress").max = state.total || 1;
  $("export-progress").value = state.done;
  $("export-text").textContent = progressText(state);
  $("export-waiting").hidden = state.status !== "queued";
  $("export-error").hidden = !state.message;
  $("export-error").textContent = state.message || "";
  $("export-download").hidden = state.status !== "done";
}

async function poll(section) {
  try {
    render(section, await api("GET", section.dataset.statusUrl));
  } catch (error) {
    console.warn("export progress:", error.message);
  }
  if (ACTIVE.has(section.dataset.status)) setTimeout(() => poll(section), POLL_MS);
}

if (typeof document !== "undefined") {
  const section = document.getElementById("export-job");
  if (section && ACTIVE.has(section.dataset.status)) setTimeout(() => poll(section), POLL_MS);
}
