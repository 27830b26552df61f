// GrabCut steps, run on the server, and undo/redo, which step the server's
// session too, so the two stay in step. A step under way, and one that
// failed to reach the server, show in the save indicator (work, in
// label_state.js) until it is applied, retried or dismissed; one the server
// refused (a 4xx: the box covers the frame, the object is finished) only says
// why: trying it again would be refused again. An object made for a refused
// box goes again.
//
// GrabCut results are merged into an object's mask by what the engine
// changed since its previous result, so manual paint and erase survive later
// strokes. A stroke on an object the server has no session of (painted by
// hand, a reviewer's fix, one kept after marking done or acceptance) sends
// the mask as it is, and the server starts GrabCut from it. If the server
// cannot follow an undo or redo, the object's engine is dropped and the next
// stroke starts GrabCut afresh from the mask.
//
// The strokes since the object's last box stay on the canvas, faintly, so
// the person sees what they already told GrabCut (until the next box, or an
// undo past them).

import { commit, edited, renderInstances } from "./label_instances.js";
import { enqueue, errorText, setBusy, showMessage } from "./label_panel.js";
import { grabcut } from "./label_server.js";
import { H, N, W, doc, editable, history, instance, lostEngines, restore, selected, target, ui, work } from "./label_state.js";
import { draw, painters, paintStrokePath } from "./label_view.js";
import { encodeCocoRle } from "./mask_codec.js";
import { paintPolyline } from "./raster.js";

// Box: the object starts again from the engine's mask. Stroke: the pixels
// the engine changed since its last answer take its new value, and the
// stroke itself is painted, so earlier manual edits elsewhere stay.
const WHAT = { box: "your GrabCut box", stroke: "your GrabCut stroke" };

function changedWork() {
  document.dispatchEvent(new CustomEvent("label:work"));
}

// Whether trying the step again could go through: the server was not
// reached, failed, or was busy with the same object; not when it refused it.
function worthRetrying(err) {
  const status = err?.status;
  return !status || status >= 500 || status === 429 || (status === 409 && err.body?.fields?.instance === "busy");
}

// kind "box" or "stroke". made: the object was made for this step (a new
// box), and goes again, with `selectedBefore` selected, if the server refuses it.
export function runGrabcut(kind, params, key = target().key, { made = false, selectedBefore = null } = {}) {
  work.running++;
  changedWork();
  return enqueue(async () => {
    setBusy(+1);
    try {
      let inst = instance(key);
      // No session on the server: it starts from the mask as the page has it.
      const start = kind === "stroke" && inst && !inst.engine ? inst.mask.slice() : null;
      const body = start ? { ...params, start: encodeCocoRle(start, W, H) } : params;
      const mask = await grabcut(kind, { instance: key, ...body });
      inst = instance(key);
      if (!inst) return;
      const before = inst.engine || start;
      if (kind === "box" || !before) {
        inst.mask = mask.slice();
      } else {
        for (let i = 0; i < N; i++) if (mask[i] !== before[i]) inst.mask[i] = mask[i];
        const points = params.points.map(([x, y]) => ({ x, y }));
        paintPolyline(inst.mask, W, H, points, params.radius, params.label === "fg" ? 1 : 0);
      }
      inst.engine = mask;
      if (kind === "box") {
        lostEngines.delete(key);
        inst.box = params.box;
        inst.strokes = [];
      } else {
        inst.strokes = [...(inst.strokes || []), { points: params.points, label: params.label, radius: params.radius }];
      }
      commit({ kind, key, params });
      if (kind === "box" && !mask.includes(1)) {
        showMessage("GrabCut found no object in this box: draw it around the whole object, or mark the object with the Object brush (F).", "info");
      }
    } catch (err) {
      showMessage(`GrabCut did not run: ${errorText(err)}`, "error");
      if (worthRetrying(err)) {
        const what = `${WHAT[kind]}${params.label === "bg" ? " (background)" : ""}`;
        work.dropped = { what, reason: errorText(err), retry: () => instance(key) && runGrabcut(kind, params, key) };
      } else if (made && instance(key) && !instance(key).mask.includes(1)) {
        doc.instances = doc.instances.filter((i) => i.key !== key); // nothing was recorded for it
        ui.selectedKey = instance(selectedBefore) ? selectedBefore : doc.instances[0]?.key ?? null;
      }
    } finally {
      setBusy(-1);
      work.running--;
      changedWork();
      renderInstances(); // also when it failed: a new object may have been made for it, or gone
    }
  });
}

// The selected object's strokes since its last box, faint, under what is being drawn now.
painters.push(() => {
  const inst = selected();
  if (!inst || inst.hidden) return;
  for (const s of inst.strokes || []) paintStrokePath(s.points.map(([x, y]) => ({ x, y })), s.label, s.radius, 0.3);
});
document.addEventListener("label:instances-rendered", draw);

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
