// Saving the labelling page: autosave (autosave.js) of the document with a
// version check, the save indicator, the conflict banner a 409 opens, the
// status buttons, the time on the frame, leaving the page only once the
// last change is saved, and the reviewer's decision.

import { Autosaver, retried, saveText } from "./autosave.js";
import { enqueue, errorText, showMessage, updateControls, updateTime } from "./label_panel.js";
import { fetchEngineMask, fetchMask, getAnnotation, postReview, postTime, putAnnotation } from "./label_server.js";
import { $, H, W, clock, config, doc, editable, loadDocument, meta, newKey, recordReplaced, snapshot } from "./label_state.js";
import { encodeCocoRle } from "./mask_codec.js";

let pendingStatus = null; // the status the next save asks for
let keepalive = false; // the next save may outlive the page

function saveBody() {
  return {
    version: meta.version,
    instances: doc.instances.map((i) => ({ key: i.key, kind: i.kind, label: i.label, mask: encodeCocoRle(i.mask, W, H) })),
    no_action_object: doc.noActionObject,
    status: pendingStatus,
  };
}

async function save() {
  const body = saveBody();
  const seconds = clock.take();
  body.time_spent_delta_s = Math.round(Math.min(seconds, 3600) * 1000) / 1000;
  try {
    const data = await putAnnotation(body, { keepalive });
    if (pendingStatus === body.status) pendingStatus = null;
    applyMeta(data);
  } catch (err) {
    clock.giveBack(seconds);
    if (err.status === 409) {
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

function showSaveState() {
  const el = $("#save-state");
  if (!el) return;
  el.dataset.state = autosaver.state;
  el.textContent = saveText(autosaver);
}

// What the server said about the annotation (a save's answer, a load): its
// version and status here, and an event for the modules that show more of it.
export function applyMeta(data) {
  meta.version = data.version;
  meta.status = data.status;
  meta.timeSpent = data.time_spent_s;
  meta.reviewComment = data.review_comment;
  meta.reviewer = data.reviewer;
  meta.author = data.author;
  meta.id = data.id;
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

export async function setStatus(status, { thenGo = null } = {}) {
  pendingStatus = status;
  autosaver.changed();
  await autosaver.flush();
  if (thenGo && (meta.status === "done" || meta.status === "reviewed") && !autosaver.dirty) window.location.href = thenGo;
}

// Leave the page only once the last change is on the server.
export async function leave(href) {
  await autosaver.flush();
  if (autosaver.dirty && !window.confirm("Your last changes are not saved yet. Leave anyway?")) return;
  window.location.href = href;
}

export async function review(decision) {
  const comment = $("#review-comment").value.trim();
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
  if (!editable) {
    $("#accept").addEventListener("click", () => review("accept"));
    $("#reject").addEventListener("click", () => review("reject"));
    return;
  }
  $("#mark-done").addEventListener("click", () => setStatus("done"));
  $("#done-next").addEventListener("click", () => setStatus("done", { thenGo: config.urls.next_unlabelled }));
  $("#reopen").addEventListener("click", () => setStatus("in_progress"));
  $("#reload-theirs").addEventListener("click", () => reloadTheirs(refresh));
  $("#keep-mine").addEventListener("click", keepMine);
  $("#save-now").addEventListener("click", () => autosaver.flush());
  // Time on the frame: counted while visible and active; flushed with the saves.
  setInterval(() => {
    clock.tick(document.visibilityState === "visible");
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
