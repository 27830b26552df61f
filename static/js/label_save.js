// Saving the labelling page: autosave (autosave.js) of the document with a
// version check, the save indicator (which counts GrabCut steps under way
// and failed), the conflict banner a 409 opens, the status buttons (and the
// question "Mark done" asks of an untouched frame), the time on the frame,
// leaving the page only once the last change is saved, and the reviewer's
// decision. On the review page a reviewer's fix saves into the author's
// annotation (its own URL) and the decision waits for it.

import { Autosaver, indicator, retried } from "./autosave.js";
import { keepHistory } from "./label_history.js";
import { commit, select } from "./label_instances.js";
import { enqueue, errorText, showMessage, updateControls, updateTime } from "./label_panel.js";
import { fetchEngineMask, fetchMask, getAnnotation, postReview, postTime, putAnnotation, putFix } from "./label_server.js";
import {
  $, H, W, clock, config, doc, editable, finished, loadDocument, meta, newKey, recordReplaced, reviewing, snapshot, ui, work,
} from "./label_state.js";
import { encodeCocoRle } from "./mask_codec.js";

let pendingStatus = null; // the status the next save asks for
let keepalive = false; // the next save may outlive the page
let markingDone = false; // "Mark done" / "Done & next" under way

function saveBody() {
  const body = {
    version: meta.version,
    instances: doc.instances.map((i) => ({ key: i.key, kind: i.kind, label: i.label, mask: encodeCocoRle(i.mask, W, H) })),
    no_action_object: doc.noActionObject,
  };
  if (!reviewing) body.status = pendingStatus;
  return body;
}

async function save() {
  const body = saveBody();
  // Nothing drawn on a frame never saved: no empty annotation is made.
  if (meta.version === 0 && !body.instances.length && !body.no_action_object && !body.status) return;
  const seconds = reviewing ? 0 : clock.take();
  if (!reviewing) body.time_spent_delta_s = Math.round(Math.min(seconds, 3600) * 1000) / 1000;
  try {
    const data = reviewing ? await putFix(body, { keepalive }) : await putAnnotation(body, { keepalive });
    if (pendingStatus === body.status) pendingStatus = null;
    applyMeta(data);
    await keepHistory({ keepalive });
  } catch (err) {
    clock.giveBack(seconds);
    if (err.status === 409 && err.body.reason === "finished") {
      finishedElsewhere();
    } else if (err.status === 409) {
      showConflict(err.body.current_version);
    } else if (err.status === 400 && err.body.error !== "csrf" && body.status) {
      // The status could not be set (nothing drawn, an empty object): say why, save the rest.
      pendingStatus = null;
      showMessage(err.message, "error");
      return save();
    } else if (!retried(err.status)) {
      showMessage(errorText(err), "error"); // refused: the whole reason, fields too
    }
    throw err;
  }
}

export const autosaver = new Autosaver({ save, delay: 500, maxWait: 1500, onState: showSaveState });

// The indicator: the saver's state, and GrabCut steps under way or dropped (never "saved" over those).
export function showSaveState() {
  const el = $("#save-state");
  if (!el) return;
  const { state, text } = indicator({ saver: autosaver, running: work.running, dropped: work.dropped });
  el.dataset.state = state;
  el.textContent = text;
  $("#retry-op").hidden = $("#dismiss-op").hidden = !work.dropped || state !== "error" || autosaver.state === "error";
}

function retryDropped() {
  const { retry } = work.dropped || {};
  work.dropped = null;
  showSaveState();
  retry?.();
}

// What the server said about the annotation (a save's answer, a load): its
// version and status here, and an event for the modules that show more of it.
export function applyMeta(data) {
  meta.version = data.version;
  meta.status = data.status;
  meta.timeSpent = data.time_spent_s;
  meta.reviewComment = data.review_comment;
  meta.reviewer = data.reviewer;
  meta.reviewedAt = data.reviewed_at;
  meta.fixedBy = data.fixed_by;
  meta.fixedAt = data.fixed_at;
  meta.author = data.author;
  meta.id = data.id;
  meta.historyUrl = data.history_url;
  updateControls();
  document.dispatchEvent(new CustomEvent("label:annotation", { detail: data }));
}

// The saved annotation, its masks and GrabCut's sessions, in place of the document.
export async function loadAnnotation() {
  const data = await getAnnotation();
  const masks = await Promise.all(data.instances.map((i) => fetchMask(i.mask_url)));
  const engines = {};
  await Promise.all(
    (data.grabcut || []).map(async (key) => {
      try {
        engines[key] = await fetchEngineMask(key);
      } catch {
        engines[key] = null;
      }
    }),
  );
  loadDocument(
    data.instances.map((i, k) => ({ key: i.key || newKey(), kind: i.kind, label: i.label, mask: masks[k], engine: engines[i.key] ?? null })),
    data.no_action_object,
  );
  applyMeta(data);
}

function showConflict(current) {
  $("#conflict-version").textContent = current;
  $("#conflict").hidden = false;
}

// A save refused because the annotation was marked done elsewhere (another
// tab): the page takes the server's status, goes read-only and keeps the
// unsaved changes; "Edit" reopens the frame and saves them.
async function finishedElsewhere() {
  try {
    applyMeta(await getAnnotation());
  } catch (err) {
    showMessage(`Could not read the saved annotation: ${errorText(err)}`, "error");
    return;
  }
  showMessage("This frame was marked done elsewhere: your changes are still here, not saved. Edit reopens it and saves them.", "error");
}

// "Load theirs": the saved version replaces the page's, as an undoable step.
async function reloadTheirs(refresh) {
  await enqueue(async () => {
    const before = snapshot();
    await loadAnnotation();
    recordReplaced(before);
    autosaver.reset();
    $("#conflict").hidden = true;
    refresh();
    showMessage("Loaded the saved version. Undo (Ctrl+Z) brings your version back.", "info");
    await keepHistory();
  });
}

// "Keep mine": save the page's version over the saved one.
async function keepMine() {
  let data;
  try {
    data = await getAnnotation();
  } catch (err) {
    showMessage(`Could not read the saved version: ${errorText(err)}`, "error");
    return;
  }
  meta.version = data.version;
  $("#conflict").hidden = true;
  autosaver.resume();
  await autosaver.flush();
}

// "Mark done" / "Done & next": on a finished frame it only moves on. An
// untouched frame is asked about first ("no action-object?"), and an empty
// object is pointed out, so nothing half-made is saved for want of a click.
// The buttons are disabled while one runs (a double click marks done once;
// the server also answers a repeat as done, not as a conflict).
export async function setStatus(status, { thenGo = null } = {}) {
  if (finished()) {
    if (thenGo) await leave(thenGo);
    return;
  }
  if (!editable || markingDone) return;
  const buttons = [$("#mark-done"), $("#done-next")];
  markingDone = true;
  buttons.forEach((b) => (b.disabled = true));
  try {
    if (status === "done" && !(await readyForDone())) return;
    pendingStatus = status;
    autosaver.changed();
    await autosaver.flush();
    if (thenGo && finished() && !autosaver.dirty) window.location.href = thenGo;
  } finally {
    markingDone = false;
    buttons.forEach((b) => (b.disabled = false));
  }
}

async function readyForDone() {
  const drawn = doc.instances.filter((i) => i.mask.includes(1));
  if (!drawn.length && !doc.noActionObject) {
    if (!(await ask("#confirm-empty"))) return false;
    doc.instances = [];
    doc.noActionObject = true;
    ui.selectedKey = null;
    commit();
    return true;
  }
  const empty = doc.instances.findIndex((i) => !i.mask.includes(1));
  if (empty >= 0) {
    showMessage(`Object ${empty + 1} is empty: draw it, or delete it (Del), before marking the frame done.`, "error");
    select(doc.instances[empty].key);
    return false;
  }
  return true;
}

// Open a <dialog> and resolve true when its [value=yes] button closes it.
function ask(selector) {
  const dialog = $(selector);
  return new Promise((resolve) => {
    dialog.addEventListener("close", () => resolve(dialog.returnValue === "yes"), { once: true });
    dialog.returnValue = "";
    dialog.showModal();
  });
}

// Leave the page only once the last change is on the server.
export async function leave(href) {
  await autosaver.flush();
  if (autosaver.dirty && !window.confirm("Your last changes are not saved yet. Leave anyway?")) return;
  window.location.href = href;
}

export async function review(decision) {
  const comment = $("#review-comment").value.trim();
  await autosaver.flush(); // a fix goes first: the decision names its version
  if (autosaver.dirty) {
    showMessage("Your fix is not saved yet (see the save indicator); decide once it is.", "error");
    return;
  }
  try {
    await postReview({ version: meta.version, decision, comment: comment || null });
    window.location.href = config.urls.next_review;
  } catch (err) {
    showMessage(errorText(err), "error");
  }
}

// Leaving or hiding the page: unsaved edits go now; so does the time
// counted since the last save, on its own (it makes no new version).
function flushOnHide() {
  if (autosaver.dirty) {
    keepalive = true;
    autosaver.flush().finally(() => (keepalive = false));
  } else if (meta.version > 0 && clock.pending >= 1) {
    const seconds = clock.take();
    postTime(Math.round(Math.min(seconds, 3600) * 1000) / 1000)
      .then(() => (meta.timeSpent += seconds))
      .catch(() => clock.giveBack(seconds));
  }
}

// The buttons and page events that save; refresh() redraws the page after
// the saved version was loaded in place of the page's.
export function wireSaving({ refresh }) {
  $("#reload-theirs").addEventListener("click", () => reloadTheirs(refresh));
  $("#keep-mine").addEventListener("click", keepMine);
  $("#save-now").addEventListener("click", () => autosaver.flush());
  $("#retry-op").addEventListener("click", retryDropped);
  $("#dismiss-op").addEventListener("click", () => {
    work.dropped = null;
    showSaveState();
  });
  document.addEventListener("label:work", showSaveState);
  if (reviewing) {
    $("#accept").addEventListener("click", () => review("accept"));
    $("#reject").addEventListener("click", () => review("reject"));
    window.addEventListener("beforeunload", (e) => autosaver.dirty && e.preventDefault());
    return;
  }
  $("#mark-done").addEventListener("click", () => setStatus("done"));
  $("#done-next").addEventListener("click", () => setStatus("done", { thenGo: config.urls.next_unlabelled }));
  // Time on the frame: counted while visible and active; flushed with the saves.
  setInterval(() => {
    clock.tick(document.visibilityState === "visible" && editable); // reading a finished frame is not labelling it
    updateTime();
    if (autosaver.retryAt !== null) showSaveState(); // the countdown to the next try
  }, 1000);
  document.addEventListener("visibilitychange", () => {
    if (document.visibilityState === "hidden") flushOnHide();
    // Back from another tab (perhaps signed in again there): try a failed save now.
    else if (autosaver.retryAt !== null) autosaver.flush();
  });
  window.addEventListener("pagehide", flushOnHide);
  window.addEventListener("beforeunload", (e) => {
    if (autosaver.dirty) {
      flushOnHide();
      e.preventDefault();
    }
  });
}
