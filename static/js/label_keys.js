// The labelling page's keyboard shortcuts (the page's "Keyboard shortcuts"
// list says the same). Keys typed into a field stay in the field; Escape
// leaves it.

import { redo, undo } from "./label_grabcut.js";
import { deleteInstance, select } from "./label_instances.js";
import { copyPrevious, propagateNext } from "./label_propagate.js";
import { autosaver, leave, review, setStatus } from "./label_save.js";
import { $, clock, config, doc, editable, ui } from "./label_state.js";
import { TOOLS, holdSpace, newObject, setBrush, setTool } from "./label_tools.js";
import { cycleView, fitView, setShowMask, showMask, zoomBy } from "./label_view.js";

function onKeyDown(event) {
  if (event.target.closest?.("input, textarea, select")) {
    if (event.key === "Escape") event.target.blur();
    return;
  }
  clock.input();
  const key = event.key.toLowerCase();
  const mod = event.ctrlKey || event.metaKey;
  if (key === " ") {
    holdSpace(true);
    event.preventDefault();
    return;
  }
  if (mod && key === "z") {
    event.preventDefault();
    if (event.shiftKey) redo();
    else undo();
    return;
  }
  if (mod && key === "y") {
    event.preventDefault();
    redo();
    return;
  }
  if (mod && key === "s") {
    event.preventDefault();
    autosaver.flush();
    return;
  }
  if (mod && key === "enter" && editable) {
    event.preventDefault();
    setStatus("done", { thenGo: config.urls.next_unlabelled });
    return;
  }
  if (mod || event.altKey) return;
  const toolKey = Object.entries(TOOLS).find(([, k]) => k === key);
  if (toolKey) return setTool(toolKey[0]);
  if (key === "[") return setBrush(ui.brushRadius / 1.25);
  if (key === "]") return setBrush(ui.brushRadius * 1.25);
  if (key === "d") return cycleView();
  if (key === "m") return setShowMask(!showMask);
  if (key === "0") return fitView();
  if (key === "+" || key === "=") return zoomBy(1.25);
  if (key === "-") return zoomBy(0.8);
  if (key === "n" && editable) return newObject();
  if (/^[1-9]$/.test(key)) return select(doc.instances[Number(key) - 1]?.key);
  if ((key === "delete" || key === "backspace") && editable && ui.selectedKey) return deleteInstance(ui.selectedKey);
  if (event.shiftKey && editable && key === "arrowright") return propagateNext();
  if (event.shiftKey && editable && key === "arrowleft") return copyPrevious();
  if (key === "arrowleft" && config.urls.previous) return leave(config.urls.previous);
  if (key === "arrowright" && config.urls.next) return leave(config.urls.next);
  if (key === "u" && config.urls.next_unlabelled) return leave(config.urls.next_unlabelled);
  if (!editable && key === "a") return review("accept");
  if (!editable && key === "r") return $("#review-comment").focus();
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
}
