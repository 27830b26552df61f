// Proposals on the labelling page. "Suggest" (the button, or S) asks the
// chosen proposer (#suggest-source: auto, depth, handled, saliency, or a
// training run) to propose the frame's action-objects; the server adds them
// beside the objects already drawn, each marked with its source ("proposed
// by depth", "proposed by run 3"), and the page loads the result
// (Ctrl+Z takes it back, like "load theirs"). A proposal is drawn with a
// dashed box and listed with Accept and Reject until it is accepted or
// edited: the server keeps that mark and clears it when the object's mask
// changes (paint, erase, GrabCut), so the page shows what each save answers.
// Rejecting a proposal deletes the object, undoably, like any deletion.

import { toScreen } from "./geometry.js";
import { deleteInstance, renderInstances } from "./label_instances.js";
import { enqueue, errorText, setBusy, showMessage } from "./label_panel.js";
import { applyMeta, autosaver, loadAnnotation } from "./label_save.js";
import { postAcceptProposal, postSuggest } from "./label_server.js";
import { $, H, W, doc, meta, recordReplaced, snapshot } from "./label_state.js";
import { draw, painters } from "./label_view.js";
import { boundingBox } from "./raster.js";

const proposals = new Map(); // instance key -> who proposed it ("depth", "run 3"), as the server last said
const boxes = new Map(); // instance key -> [x0, y0, x1, y1) of its mask, as last drawn in the list

// Ask for proposals; the saved result replaces the page's document.
export async function suggest(refresh) {
  await autosaver.flush();
  if (autosaver.dirty) {
    showMessage("Suggest waits for your last changes to be saved; try again once they are.", "error");
    return;
  }
  const choice = $("#suggest-source").selectedOptions[0];
  const body = { source: choice.value, run_id: choice.dataset.run ? Number(choice.dataset.run) : null };
  await enqueue(async () => {
    setBusy(+1);
    $("#suggest").disabled = true;
    try {
      const data = await postSuggest({ version: meta.version, ...body });
      if (data.queued) {
        showMessage(data.message, "info");
        return;
      }
      const before = snapshot();
      await loadAnnotation();
      recordReplaced(before);
      autosaver.reset();
      refresh();
      $("#suggest-result").textContent = data.suggestion.message;
      $("#suggest-result").hidden = false;
      const n = data.suggestion.proposals.length;
      showMessage(n ? `${n} proposal${n === 1 ? "" : "s"}: accept or reject each (Ctrl+Z takes them back).` : data.suggestion.message, "info");
    } catch (err) {
      showMessage(`Suggest: ${errorText(err)}`, "error");
    } finally {
      $("#suggest").disabled = false;
      setBusy(-1);
    }
  });
}

async function accept(key) {
  await autosaver.flush(); // the accept names the version the server has
  await enqueue(async () => {
    try {
      applyMeta(await postAcceptProposal({ version: meta.version, key }));
    } catch (err) {
      showMessage(`Accept: ${errorText(err)}`, "error");
    }
  });
}

// The server's word on which objects are still proposals (every save's and load's answer).
function onAnnotation(event) {
  const before = [...proposals].join();
  proposals.clear();
  for (const inst of event.detail.instances || []) {
    const source = inst.proposal_source;
    if (source) proposals.set(inst.key, source === "model" ? `run ${inst.proposed_by_run_id}` : source);
  }
  if ([...proposals].join() !== before) renderInstances(); // only then: a redrawn list would take a field's focus
}

// Each proposal in the list: who proposed it, Accept and Reject; its box for the canvas.
function decorate() {
  boxes.clear();
  for (const li of document.querySelectorAll("#instances .instance")) {
    const key = li.dataset.key;
    const by = proposals.get(key);
    if (by === undefined) continue;
    const inst = doc.instances.find((i) => i.key === key);
    const box = inst && boundingBox(inst.mask, W, H);
    if (box) boxes.set(key, box);
    li.classList.add("proposed");
    const row = document.createElement("div");
    row.className = "proposal";
    row.innerHTML = `
      <span class="proposal-tag">proposed by ${by}</span>
      <button type="button" class="accept-proposal ok" title="Keep this object as it is">Accept</button>
      <button type="button" class="reject-proposal" title="Delete this object">Reject</button>`;
    row.querySelector(".accept-proposal").addEventListener("click", () => accept(key));
    row.querySelector(".reject-proposal").addEventListener("click", () => deleteInstance(key));
    li.append(row);
  }
  draw();
}

// On the canvas: a dashed box around each proposal, and who proposed it.
function paintProposals(ctx, view) {
  ctx.save();
  ctx.font = "600 12px system-ui, sans-serif";
  ctx.textBaseline = "bottom";
  for (const [key, [x0, y0, x1, y1]] of boxes) {
    if (!doc.instances.some((i) => i.key === key)) continue;
    // A few screen pixels outside the mask, so the selected object's own outline stays visible.
    const a = toScreen(view, x0, y0);
    const b = toScreen(view, x1, y1);
    a.x -= 4;
    a.y -= 4;
    ctx.setLineDash([7, 5]);
    ctx.lineWidth = 2;
    ctx.strokeStyle = "#ffd43b";
    ctx.strokeRect(a.x, a.y, b.x + 4 - a.x, b.y + 4 - a.y);
    ctx.setLineDash([]);
    const text = `proposed by ${proposals.get(key)}`;
    const width = ctx.measureText(text).width + 8;
    const top = Math.max(16, a.y);
    ctx.fillStyle = "rgba(20, 23, 29, 0.85)";
    ctx.fillRect(a.x, top - 16, width, 16);
    ctx.fillStyle = "#ffd43b";
    ctx.fillText(text, a.x + 4, top - 2);
  }
  ctx.restore();
}

function onKeyDown(event) {
  if (event.target.closest?.("input, textarea, select") || event.ctrlKey || event.metaKey || event.altKey) return;
  if (event.key === "s" || event.key === "S") {
    event.preventDefault();
    $("#suggest").click();
  }
}

export function wireSuggest({ refresh }) {
  $("#suggest").addEventListener("click", (event) => {
    event.currentTarget.blur();
    suggest(refresh);
  });
  document.addEventListener("label:annotation", onAnnotation);
  document.addEventListener("label:instances-rendered", decorate);
  document.addEventListener("keydown", onKeyDown);
  painters.push(paintProposals);
}
