// The labelling page (and the review page, read-only until the reviewer
// fixes the mask): a canvas with zoom and pan, GrabCut box and fg/bg strokes
// run on the server, manual paint and erase, polygons, an editable box per
// object, several objects per frame, undo/redo kept on the server, autosave
// with a version check.
//
// This entry module wires the page's parts together:
//   label_state.js      config, the document, editable, the tool state, the undo history
//   label_view.js       the canvas: frame, masks and outlines, zoom and pan, brightness
//   label_tools.js      box, fg/bg strokes, paint/erase, brush, pointer input
//   label_shapes.js     the selected object's editable box, the polygon tool
//   label_grabcut.js    GrabCut steps and undo/redo, kept in step with the server
//   label_instances.js  the list of action-objects (show/hide), commit() of an edit
//   label_save.js       autosave, the save indicator, the 409 banner, status, review
//   label_history.js    the undo history kept on the server across reloads
//   label_lock.js       read-only done/reviewed frames and "Edit", the reviewer's "Fix"
//   label_presence.js   who else has this frame open or in progress
//   label_server.js     every call to the server (through api.js)
//   label_panel.js      status badge, time, messages, the busy spinner
//   label_keys.js       keyboard shortcuts and the "?" overlay that lists them
//   label_propagate.js  propagate to the next frame, copy from the previous one
//   label_filmstrip.js  the sequence's frames under the canvas, "go to frame N"
//   label_suggest.js    a trained model's proposals: Suggest, accept, reject

import { redo, undo } from "./label_grabcut.js";
import { wireFilmstrip } from "./label_filmstrip.js";
import { loadHistory } from "./label_history.js";
import { refresh, wireInstances } from "./label_instances.js";
import { toggleHelp, wireKeys } from "./label_keys.js";
import { updateLock, wireLock } from "./label_lock.js";
import { errorText, showMessage } from "./label_panel.js";
import { wirePresence } from "./label_presence.js";
import { wirePropagate } from "./label_propagate.js";
import { autosaver, leave, loadAnnotation, showSaveState, wireSaving } from "./label_save.js";
import { wireSuggest } from "./label_suggest.js";
import { $, $$, H, W, doc, editable, history, meta, reviewing, ui, work } from "./label_state.js";
import { newObject, setBrush, setTool, wireTools } from "./label_tools.js";
import { clientPoint, display, fitView, resize, setBaseView, setDisplay, setOpacity, setShowMask, stage, view, zoomBy } from "./label_view.js";
import { encodeCocoRle } from "./mask_codec.js";
import { countSet } from "./raster.js";

const DISPLAY_KEY = "egonet.label.display"; // brightness and contrast follow the person from frame to frame

function wireDisplay() {
  const saved = JSON.parse(localStorage.getItem(DISPLAY_KEY) || "{}");
  const apply = () => {
    const brightness = Number($("#brightness").value) / 100;
    const contrast = Number($("#contrast").value) / 100;
    setDisplay({ brightness, contrast });
    $("#brightness-value").textContent = `${Math.round(brightness * 100)}%`;
    $("#contrast-value").textContent = `${Math.round(contrast * 100)}%`;
    localStorage.setItem(DISPLAY_KEY, JSON.stringify({ brightness, contrast }));
  };
  if (saved.brightness) $("#brightness").value = Math.round(saved.brightness * 100);
  if (saved.contrast) $("#contrast").value = Math.round(saved.contrast * 100);
  $("#brightness").addEventListener("input", apply);
  $("#contrast").addEventListener("input", apply);
  $("#display-reset").addEventListener("click", () => {
    $("#brightness").value = $("#contrast").value = 100;
    apply();
  });
  apply();
}

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
  $("#undo").addEventListener("click", undo);
  $("#redo").addEventListener("click", redo);
  $("#add-instance").addEventListener("click", newObject);
  wireDisplay();
  wireInstances({ save: () => autosaver.changed() });
  wireSaving({ refresh });
  wireLock();
  wirePropagate();
  wireFilmstrip();
  wirePresence();
  if (!reviewing) wireSuggest({ refresh });
  // Whatever fails without its own handler is said in words too.
  window.addEventListener("unhandledrejection", (e) => showMessage(`Something failed: ${errorText(e.reason)}`, "error"));
  document.addEventListener("label:image-failed", (e) =>
    showMessage(`The frame's ${e.detail.toUpperCase()} image could not be loaded: reload the page, or ask an admin to run media-check.`, "error"),
  );
}

// For tests and the console: what the page holds, without reaching into it.
window.labelPage = {
  get version() {
    return meta.version;
  },
  get status() {
    return meta.status;
  },
  get saveState() {
    return autosaver.state;
  },
  get editable() {
    return editable;
  },
  get undoSteps() {
    return history.done.length;
  },
  get scale() {
    return view.scale;
  },
  get display() {
    return { ...display };
  },
  get dropped() {
    return work.dropped && { what: work.dropped.what, reason: work.dropped.reason };
  },
  instances: () =>
    doc.instances.map((i) => ({ key: i.key, kind: i.kind, label: i.label, area: countSet(i.mask), hasEngine: !!i.engine, hidden: i.hidden, box: i.box })),
  get selected() {
    return ui.selectedKey;
  },
  maskRle: (k) => encodeCocoRle(doc.instances[k].mask, W, H),
  // Where image point (x, y) is in the window (for driving the page from tests).
  clientPoint,
  help: toggleHelp,
};

async function start() {
  wire();
  setTool(ui.tool);
  setBrush(ui.brushRadius);
  setBaseView("rgb");
  try {
    await loadAnnotation();
    await loadHistory();
    updateLock(); // editable unless finished; after a failed load it stays read-only
  } catch (err) {
    showMessage(`Could not load the annotation: ${errorText(err)}. Reload the page to try again.`, "error");
  }
  refresh();
  showSaveState();
  $("#label-app").dataset.ready = "1";
}

start();
