// GrabCut steps, run on the server, and undo/redo, which step the server's
// session too, so the two stay in step. A step under way, and one that
// failed, show in the save indicator (work, in label_state.js) until it is
// applied, retried or dismissed.
//
// GrabCut results are merged into an object's mask by what the engine
// changed since its previous result, so manual paint and erase survive later
// strokes. If the server cannot follow an undo or redo, the object's engine
// is dropped and GrabCut starts afresh with the next box.

import { commit, edited, renderInstances } from "./label_instances.js";
import { enqueue, errorText, setBusy, showMessage } from "./label_panel.js";
import { grabcut } from "./label_server.js";
import { H, N, W, editable, history, instance, lostEngines, restore, target, work } from "./label_state.js";
import { paintPolyline } from "./raster.js";

// Box: the object starts again from the engine's mask. Stroke: the pixels
// the engine changed since its last answer take its new value, and the
// stroke itself is painted, so earlier manual edits elsewhere stay.
const WHAT = { box: "your GrabCut box", stroke: "your GrabCut stroke" };

function changedWork() {
  document.dispatchEvent(new CustomEvent("label:work"));
}

export function runGrabcut(kind, params, key = target().key) {
  work.running++;
  changedWork();
  return enqueue(async () => {
    setBusy(+1);
    try {
      const mask = await grabcut(kind, { instance: key, ...params });
      const inst = instance(key);
      if (!inst) return;
      if (kind === "box" || !inst.engine) {
        inst.mask = mask.slice();
      } else {
        for (let i = 0; i < N; i++) if (mask[i] !== inst.engine[i]) inst.mask[i] = mask[i];
        const points = params.points.map(([x, y]) => ({ x, y }));
        paintPolyline(inst.mask, W, H, points, params.radius, params.label === "fg" ? 1 : 0);
      }
      inst.engine = mask;
      if (kind === "box") {
        lostEngines.delete(key);
        inst.box = params.box;
      }
      commit({ kind, key, params });
      if (kind === "box" && !mask.includes(1)) {
        showMessage("GrabCut found no object in this box: draw it around the whole object, or mark the object with the Object brush (F).", "info");
      }
    } catch (err) {
      showMessage(`GrabCut did not run: ${errorText(err)}`, "error");
      const what = `${WHAT[kind]}${params.label === "bg" ? " (background)" : ""}`;
      work.dropped = { what, reason: errorText(err), retry: () => instance(key) && runGrabcut(kind, params, key) };
    } finally {
      setBusy(-1);
      work.running--;
      changedWork();
      renderInstances(); // also when it failed: a new object may have been made for it
    }
  });
}

async function replayOnServer(op, undoing) {
  if (lostEngines.has(op.key)) return;
  try {
    if (undoing) await grabcut("undo", { instance: op.key });
    else await grabcut(op.kind, { instance: op.key, ...op.params });
  } catch (err) {
    lostEngines.add(op.key);
    const inst = instance(op.key);
    if (inst) inst.engine = null;
    // The mask is back as it was; only GrabCut's memory of the object is gone.
    showMessage(`GrabCut could not follow the ${undoing ? "undo" : "redo"} (${errorText(err)}): the mask is restored; draw the object's box again before more strokes.`, "info");
  }
}

export function undo() {
  if (!editable) return;
  enqueue(async () => {
    const entry = history.undo();
    if (!entry) return;
    restore(entry.before);
    if (entry.op) await replayOnServer(entry.op, true);
    edited();
  });
}

export function redo() {
  if (!editable) return;
  enqueue(async () => {
    const entry = history.redo();
    if (!entry) return;
    restore(entry.after);
    if (entry.op) await replayOnServer(entry.op, false);
    edited();
  });
}
