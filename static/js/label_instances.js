// The labelling page's list of action-objects: adding, selecting, showing
// or hiding (on the canvas only; not saved) and deleting them, their kind
// and name, the "no action-object" flag, and commit(), which records an
// edit in the undo history and lets autosave send it (the entry module
// hands wireInstances autosave's changed()).

import { updateControls } from "./label_panel.js";
import { $, N, doc, editable, instance, makeInstance, record, ui } from "./label_state.js";
import { renderOverlay } from "./label_view.js";
import { countSet } from "./raster.js";

let saveEdit = () => {}; // set by wireInstances

// Redraw everything that shows the document.
export function refresh() {
  renderOverlay();
  renderInstances();
  updateControls();
}

// The document changed (restored from the history, say): show it and save it.
export function edited() {
  refresh();
  saveEdit();
}

// Record the edit just made (undoable) and let autosave send it.
export function commit(op = null) {
  record(op);
  edited();
}

export function addInstance() {
  const inst = makeInstance();
  doc.instances.push(inst);
  ui.selectedKey = inst.key;
  doc.noActionObject = false;
  commit();
}

export function deleteInstance(key) {
  const i = doc.instances.findIndex((x) => x.key === key);
  if (i < 0) return;
  doc.instances.splice(i, 1);
  if (ui.selectedKey === key) ui.selectedKey = doc.instances[Math.min(i, doc.instances.length - 1)]?.key ?? null;
  commit();
}

export function select(key) {
  if (!instance(key)) return;
  ui.selectedKey = key;
  renderOverlay();
  renderInstances();
}

// Show or hide an object on the canvas (the selected one when no key is given).
export function toggleHidden(key = ui.selectedKey) {
  const inst = instance(key);
  if (!inst) return;
  inst.hidden = !inst.hidden;
  renderOverlay();
  renderInstances();
}

// The checkbox: marking the frame empty deletes what is drawn, once confirmed.
function setNoActionObject(event) {
  if (!editable) {
    event.target.checked = doc.noActionObject;
    return;
  }
  const drawn = doc.instances.filter((i) => i.mask.some((v) => v)).length;
  if (event.target.checked && drawn && !window.confirm(`Delete the ${drawn} drawn object(s) and mark the frame "no action-object"?`)) {
    event.target.checked = false;
    return;
  }
  doc.noActionObject = event.target.checked;
  if (doc.noActionObject) {
    doc.instances = [];
    ui.selectedKey = null;
  }
  commit();
}

export function wireInstances({ save }) {
  saveEdit = save;
  $("#no-ao").addEventListener("change", setNoActionObject);
}

export function renderInstances() {
  const list = $("#instances");
  list.replaceChildren();
  doc.instances.forEach((inst, k) => {
    const li = document.createElement("li");
    li.className = "instance" + (inst.key === ui.selectedKey ? " selected" : "") + (inst.hidden ? " hidden-object" : "");
    li.dataset.key = inst.key;
    const area = countSet(inst.mask);
    const [r, g, b] = inst.colour;
    li.innerHTML = `
      <div class="instance-head">
        <button type="button" class="pick" title="Select (${k + 1})">
          <span class="swatch"></span>
          <span class="name">Object ${k + 1}</span>
          <span class="area">${area ? `${((100 * area) / N).toFixed(1)}%` : "empty"}</span>
        </button>
        <button type="button" class="visibility quiet"
          title="${inst.hidden ? "Show" : "Hide"} this object on the image (V: the selected one)">${inst.hidden ? "Show" : "Hide"}</button>
      </div>
      <div class="instance-fields">
        <select class="kind" aria-label="kind" ${editable ? "" : "disabled"}>
          <option value="">kind…</option><option value="tactile">tactile</option><option value="visual">visual</option>
        </select>
        <input class="label" list="object-classes" placeholder="class (optional)" maxlength="120" aria-label="name" ${editable ? "" : "disabled"}>
        ${editable ? '<button type="button" class="delete" title="Delete object (Del)" aria-label="delete">✕</button>' : ""}
      </div>`;
    li.querySelector(".swatch").style.background = `rgb(${r}, ${g}, ${b})`; // a style attribute would break the CSP
    li.querySelector(".kind").value = inst.kind || "";
    li.querySelector(".label").value = inst.label || "";
    li.querySelector(".pick").addEventListener("click", () => select(inst.key));
    li.querySelector(".visibility").addEventListener("click", (e) => {
      e.currentTarget.blur();
      toggleHidden(inst.key);
    });
    li.querySelector(".kind").addEventListener("change", (e) => {
      inst.kind = e.target.value || null;
      commit();
    });
    li.querySelector(".label").addEventListener("change", (e) => {
      inst.label = e.target.value.trim() || null;
      commit();
    });
    li.querySelector(".delete")?.addEventListener("click", () => deleteInstance(inst.key));
    list.append(li);
  });
  $("#instances-empty").hidden = doc.instances.length > 0;
  document.dispatchEvent(new CustomEvent("label:instances-rendered")); // others add to the items (proposals)
}
