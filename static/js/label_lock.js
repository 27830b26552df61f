// Read-only until asked: a done or reviewed frame opens read-only, with a
// banner that says so and an "Edit" that says what editing does to its
// review (done: it goes back in progress, to be marked done again; reviewed:
// its acceptance is withdrawn too). Edit reopens it on the server (with the
// version check) and the tools come back. The server refuses any change of
// a finished annotation that was not reopened, so no page can demote one
// silently.
//
// On the review page the annotation is read-only until "Fix the mask": the
// reviewer's changes then save into the author's annotation (recorded as
// fixed by the reviewer; it stays done), and Accept or Reject decides on
// the fixed version.

import { renderInstances } from "./label_instances.js";
import { errorText, showMessage, updateControls } from "./label_panel.js";
import { applyMeta, autosaver } from "./label_save.js";
import { postReopen } from "./label_server.js";
import { keepHistory } from "./label_history.js";
import { updateCarryButtons } from "./label_propagate.js";
import { $, $$, config, editable, finished, meta, reviewing, setEditable, ui } from "./label_state.js";
import { readOnlyReason, setTool } from "./label_tools.js";

const DAY = { year: "numeric", month: "short", day: "numeric", hour: "2-digit", minute: "2-digit" };
let fixing = false;
// The editing controls; those the template disables for good (no depth on this frame) stay so.
const controls = $$(".edit-only button, .edit-only input, .edit-only select, button.edit-only");
controls.forEach((el) => (el.dataset.alwaysOff = el.disabled ? "1" : ""));

// A moment in words: the time alone when it was today.
export function when(iso) {
  if (!iso) return "";
  const t = new Date(iso);
  const today = t.toDateString() === new Date().toDateString();
  return today ? t.toLocaleTimeString(undefined, { hour: "2-digit", minute: "2-digit" }) : t.toLocaleString(undefined, DAY);
}

// Whether the page may edit, from the annotation's status; the controls follow.
export function updateLock() {
  const was = editable;
  setEditable(reviewing ? fixing : !finished());
  const app = $("#label-app");
  app.dataset.editable = editable ? "1" : "0";
  controls.forEach((el) => (el.disabled = !editable || el.dataset.alwaysOff === "1"));
  updateCarryButtons(); // Copy also needs a previous frame
  const banner = $("#locked");
  if (banner) {
    banner.hidden = reviewing || editable;
    if (!editable && !reviewing) {
      const reviewed = meta.status === "reviewed";
      $("#locked-title").textContent = reviewed
        ? `Accepted${meta.reviewer ? ` by ${meta.reviewer}` : ""}${meta.reviewedAt ? ` on ${when(meta.reviewedAt)}` : ""}: read-only.`
        : "Done, waiting for review: read-only.";
      $("#locked-effect").textContent = reviewed
        ? "Edit withdraws the acceptance: the frame goes back in progress, to be marked done and reviewed again."
        : "Edit puts the frame back in progress: mark it done again to send it for review.";
    }
  }
  const saveBox = $("#save-box");
  if (saveBox && reviewing) saveBox.hidden = !fixing;
  if (was !== editable) {
    renderInstances(); // the objects' fields follow
    if (editable) setTool(ui.tool);
  }
  if (!editable) $("#tool-hint").textContent = readOnlyReason();
  updateControls();
}

// "Edit": reopen the finished annotation, with the version check.
async function edit() {
  try {
    applyMeta(await postReopen({ version: meta.version }));
  } catch (err) {
    showMessage(`Could not reopen the frame: ${errorText(err)}`, "error");
    return;
  }
  updateLock();
  showMessage("Back in progress: your changes save as usual; mark the frame done again when it is right.", "info");
  autosaver.resume(); // changes made meanwhile elsewhere-refused go now
  keepHistory();
}

// "Fix the mask" on the review page.
function fix() {
  fixing = true;
  updateLock();
  setTool("box");
  $("#fix").hidden = true;
  $("#fixing").hidden = false;
  showMessage(`Fixing ${meta.author}'s annotation: changes save into it as you go.`, "info");
}

export function wireLock() {
  document.addEventListener("label:annotation", updateLock);
  $("#edit")?.addEventListener("click", edit);
  $("#fix")?.addEventListener("click", fix);
  if (reviewing && config.own) $("#fix").disabled = true;
  // The review queue's "Fix" link opens the review page ready to fix.
  if (reviewing && !config.own && location.hash === "#fix") {
    document.addEventListener("label:annotation", () => { if (!fixing) fix(); }, { once: true });
  }
}
