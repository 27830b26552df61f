// The labelling page (and, read-only, the review page): a canvas with zoom
// and pan, GrabCut box and fg/bg strokes run on the server, manual paint and
// erase, several objects per frame, undo/redo, autosave with a version check.
//
// This entry module wires the page's parts together:
//   label_state.js      config, the document, the tool state, the undo history
//   label_view.js       the canvas: frame, masks, zoom and pan
//   label_tools.js      box, fg/bg strokes, paint/erase, brush, pointer input
//   label_grabcut.js    GrabCut steps and undo/redo, kept in step with the server
//   label_instances.js  the list of action-objects, commit() of an edit
//   label_save.js       autosave, the save indicator, the 409 banner, status, review
//   label_server.js     every call to the server (through api.js)
//   label_panel.js      status badge, time, messages, the busy spinner
//   label_keys.js       keyboard shortcuts
//   label_propagate.js  propagate to the next frame, copy from the previous one
//   label_filmstrip.js  the sequence's frames under the canvas, "go to frame N"
//   label_suggest.js    a trained model's proposals: Suggest, accept, reject

import { redo, undo } from "./label_grabcut.js";
import { wireFilmstrip } from "./label_filmstrip.js";
import { refresh, wireInstances } from "./label_instances.js";
import { wireKeys } from "./label_keys.js";
import { errorText, showMessage } from "./label_panel.js";
import { wirePropagate } from "./label_propagate.js";
import { autosaver, leave, loadAnnotation, wireSaving } from "./label_save.js";
import { wireSuggest } from "./label_suggest.js";
import { $, $$, H, W, doc, editable, meta, ui } from "./label_state.js";
import { newObject, setBrush, setTool, wireTools } from "./label_tools.js";
import { clientPoint, fitView, resize, setBaseView, setOpacity, setShowMask, stage, zoomBy } from "./label_view.js";
import { encodeCocoRle } from "./mask_codec.js";
import { countSet } from "./raster.js";

function wire() {
  new ResizeObserver(resize).observe(stage);
  wireTools();
  wireKeys();
  // Tool and zoom buttons give the keyboard back to the canvas (Space pans, it must not click them).
  $$(".toolbar button, .zoom button").forEach((b) => b.addEventListener("click", () => b.blur()));
  $$("[data-view]").forEach((b) => b.addEventListener("click", () => setBaseView(b.dataset.view)));
  $("#show-mask").addEventListener("change", (e) => setShowMask(e.target.checked));
  $("#opacity").addEventListener("input", (e) => setOpacity(Number(e.target.value) / 100));
  $("#zoom-fit").addEventListener("click", fitView);
  $("#zoom-in").addEventListener("click", () => zoomBy(1.25));
  $("#zoom-out").addEventListener("click", () => zoomBy(0.8));
  $$("a[data-flush]").forEach((a) =>
    a.addEventListener("click", (e) => {
      e.preventDefault();
      leave(a.href);
    }),
  );
  if (editable) {
    $("#undo").addEventListener("click", undo);
    $("#redo").addEventListener("click", redo);
    $("#add-instance").addEventListener("click", newObject);
  }
  wireInstances();
  wireSaving({ refresh });
  wirePropagate();
  wireFilmstrip();
  if (editable) wireSuggest({ refresh });
}

// For tests and the console: what the page holds, without reaching into it.
window.labelPage = {
  get version() {
    return meta.version;
  },
  get saveState() {
    return autosaver.state;
  },
  instances: () => doc.instances.map((i) => ({ key: i.key, kind: i.kind, label: i.label, area: countSet(i.mask), hasEngine: !!i.engine })),
  maskRle: (k) => encodeCocoRle(doc.instances[k].mask, W, H),
  // Where image point (x, y) is in the window (for driving the page from tests).
  clientPoint,
};

async function start() {
  wire();
  setTool(ui.tool);
  setBrush(ui.brushRadius);
  setBaseView("rgb");
  try {
    await loadAnnotation();
  } catch (err) {
    showMessage(`Could not load the annotation: ${errorText(err)}`, "error");
  }
  refresh();
  $("#label-app").dataset.ready = "1";
}

start();
