// What the labelling page tells the person outside the canvas: the status
// badge, the undo/redo buttons, the reviewer's note, the time spent, the
// busy spinner and the passing messages. Also the queue that runs GrabCut
// calls, undo and redo one at a time, so the server sees them in page order.

import { ApiError } from "./api.js";
import { $, clock, doc, editable, finished, history, meta, reviewing } from "./label_state.js";

let busy = 0;
let messageTimer = null;
let queue = Promise.resolve();

export function enqueue(task) {
  queue = queue.then(task).catch((err) => showMessage(errorText(err), "error"));
  return queue;
}

export function setBusy(delta) {
  busy += delta;
  $("#busy").hidden = busy <= 0;
}

export function showMessage(text, kind = "info") {
  const el = $("#message");
  el.textContent = text;
  el.className = `message ${kind}`;
  el.hidden = false;
  clearTimeout(messageTimer);
  messageTimer = setTimeout(() => (el.hidden = true), kind === "error" ? 7000 : 4000);
}

// The server's reason in words: the API's "field: reason" messages lose
// their field's name, and the notes on other fields are added only to a
// message about fields (a request with several bad ones); a sentence stays
// as it is (no "(status: is reviewed)" after "this one was accepted already").
export function errorText(err) {
  if (!(err instanceof ApiError)) return err?.message || String(err);
  const message = err.message;
  const fields = Object.entries(err.body?.fields || {});
  const named = fields.find(([k]) => /^[a-z_]+$/.test(k) && message.startsWith(`${k}: `));
  const text = named ? message.slice(named[0].length + 2) : message;
  const aboutFields = fields.some(([k]) => message.includes(k));
  const extra = aboutFields ? fields.filter(([k]) => !message.includes(k)) : [];
  return extra.length ? `${text} (${extra.map(([k, v]) => `${k}: ${v}`).join("; ")})` : text;
}

export function updateControls() {
  const badge = $("#status-badge");
  badge.className = `status status-${meta.status}`;
  badge.textContent = meta.status.replace("_", " ");
  const tile = document.querySelector(".film-frame.current"); // the filmstrip follows this frame's status
  if (tile) tile.dataset.status = meta.status;
  $("#no-ao").checked = doc.noActionObject;
  $("#undo").disabled = !editable || !history.canUndo;
  $("#redo").disabled = !editable || !history.canRedo;
  if (!reviewing) {
    $("#mark-done").hidden = finished();
    $("#done-next").hidden = finished();
  }
  const banner = $("#review-note");
  const fixed = meta.fixedBy ? `Fixed in review by ${meta.fixedBy}.` : "";
  if (meta.reviewComment || fixed) {
    banner.hidden = false;
    banner.classList.toggle("rejected", meta.status === "rejected");
    const who = meta.reviewer ? ` by ${meta.reviewer}` : "";
    $("#review-note-title").textContent = !meta.reviewComment ? "" : meta.status === "rejected" ? `Returned${who} — please fix:` : `Reviewer's note${who}:`;
    $("#review-note-text").textContent = [meta.reviewComment, fixed].filter(Boolean).join(" ");
  } else {
    banner.hidden = true;
  }
  updateTime();
}

export function updateTime() {
  const total = Math.round(meta.timeSpent + (reviewing ? 0 : clock.pending));
  $("#time-spent").textContent = `${Math.floor(total / 60)}:${String(total % 60).padStart(2, "0")}`;
}
