// The labelling page's keyboard shortcuts (the "?" overlay lists them, and
// the README's list is the same: a test compares the two). Keys typed into a
// field stay in the field; Escape leaves it. While the page is read-only the
// keys that would edit say why they do nothing.

import { redo, undo } from "./label_grabcut.js";
import { deleteInstance, select, toggleHidden } from "./label_instances.js";
import { showMessage } from "./label_panel.js";
import { copyPrevious, propagateNext, propagatePrevious } from "./label_propagate.js";
import { autosaver, leave, review, setStatus } from "./label_save.js";
import { polygonKey } from "./label_shapes.js";
import { $, clock, config, doc, editable, reviewing, ui } from "./label_state.js";
import { TOOLS, holdSpace, newObject, readOnlyReason, setBrush, setTool } from "./label_tools.js";
import { cycleView, draw, fitView, setShowMask, showMask, zoomBy } from "./label_view.js";

export function toggleHelp(open = $("#help").hidden) {
  $("#help").hidden = !open;
}

// Keys that change the document: while read-only they only say why not.
function edits(action) {
  return () => (editable ? action() : showMessage(readOnlyReason(), "info"));
}

const PLAIN = {
  "[": () => setBrush(ui.brushRadius / 1.25),
  "]": () => setBrush(ui.brushRadius * 1.25),
  d: cycleView,
  m: () => setShowMask(!showMask),
  v: () => toggleHidden(),
  0: fitView,
  "+": () => zoomBy(1.25),
  "=": () => zoomBy(1.25),
  "-": () => zoomBy(0.8),
  "?": () => toggleHelp(),
  n: edits(newObject),
  delete: edits(() => ui.selectedKey && deleteInstance(ui.selectedKey)),
  backspace: edits(() => ui.selectedKey && deleteInstance(ui.selectedKey)),
};

function onKeyDown(event) {
  if (event.target.closest?.("input, textarea, select")) {
    if (event.key === "Escape") event.target.blur();
    return;
  }
  clock.input();
  const key = event.key.toLowerCase();
  const mod = event.ctrlKey || event.metaKey;
  if (key === "escape" && !$("#help").hidden) return toggleHelp(false);
  if (!mod && polygonKey(key)) return event.preventDefault();
  if (key === "escape" && ui.drag) {
    ui.drag = null;
    return draw();
  }
  if (key === " ") {
    holdSpace(true);
    event.preventDefault();
    return;
  }
  if (mod && (key === "z" || key === "y")) {
    event.preventDefault();
    if (!editable) return showMessage(readOnlyReason(), "info");
    return key === "y" || event.shiftKey ? redo() : undo();
  }
  if (mod && key === "s") {
    event.preventDefault();
    autosaver.flush();
    return;
  }
  if (mod && key === "enter" && !reviewing) {
    event.preventDefault();
    setStatus("done", { thenGo: config.urls.next_unlabelled });
    return;
  }
  if (mod && event.shiftKey && key === "arrowleft" && !reviewing) {
    event.preventDefault();
    return propagatePrevious();
  }
  if (mod || event.altKey) return;
  const tool = Object.entries(TOOLS).find(([, k]) => k === key)?.[0];
  if (tool) return tool === "pan" || editable ? setTool(tool) : showMessage(readOnlyReason(), "info");
  if (PLAIN[key]) return PLAIN[key]();
  if (/^[1-9]$/.test(key)) return select(doc.instances[Number(key) - 1]?.key);
  if (reviewing) {
    if (key === "a") return review("accept");
    if (key === "r") return $("#review-comment").focus();
    return;
  }
  if (event.shiftKey && key === "arrowright") return propagateNext();
  if (event.shiftKey && key === "arrowleft") return edits(copyPrevious)();
  if (key === "arrowleft" && config.urls.previous) return leave(config.urls.previous);
  if (key === "arrowright" && config.urls.next) return leave(config.urls.next);
  if (key === "u" && config.urls.next_unlabelled) return leave(config.urls.next_unlabelled);
}

function onKeyUp(event) {
  if (event.key === " " && !event.target.closest?.("input, textarea, select")) {
    event.preventDefault(); // a focused button would take the space as a click
    holdSpace(false);
  }
}

export function wireKeys() {
  document.addEventListener("keydown", onKeyDown);
  document.addEventListener("keyup", onKeyUp);
  $("#help-open").addEventListener("click", (e) => {
    e.currentTarget.blur();
    toggleHelp(true);
  });
  $("#help-close").addEventListener("click", () => toggleHelp(false));
  $("#help").addEventListener("click", (e) => e.target === e.currentTarget && toggleHelp(false));
}
