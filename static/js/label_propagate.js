// "Propagate" (Shift+→ next, Ctrl+Shift+← previous) and "Copy from previous
// frame" (Shift+←): the server carries every object of the user's annotation
// to the adjacent frame of the sequence, each mask refined there, and saves
// it as the user's in-progress annotation of that frame. The page saves
// first (the server carries what is saved), then opens the frame that
// received it.
//
// "Frames" (1-50) carries on frame after frame, as a chain of requests of at
// most config.carry_request.frames frames (fewer with many objects: one
// request stays short), showing its progress under the buttons. The server
// stops at the first frame whose result looks unsure (saved, so the page
// opens it to be fixed), before a frame that has the user's work, or at the
// sequence's end; the page opens the last carried frame and says there why
// it stopped (kept in sessionStorage across the page load).
//
// Existing work is never replaced silently: when the first target frame
// already has the user's objects the server answers 409 and the page shows
// a banner that offers "Replace", which sends replace=true with the version
// the server reported (a newer one is refused again); a finished target is
// refused outright.

import { autosaver, leave } from "./label_save.js";
import { errorText, setBusy, showMessage } from "./label_panel.js";
import { carry } from "./label_server.js";
import { $, config, doc, editable, reviewing } from "./label_state.js";

const WHAT = {
  next: { busy: "Propagating to the next frame", target: "the next frame" },
  previous: { busy: "Propagating to the previous frame", target: "the previous frame" },
  copy_previous: { busy: "Copying from the previous frame…", target: "this frame" },
};
const NOTE = "egonet.carry-note"; // sessionStorage: {frame, text, kind} for the frame the page opens next

let running = false;

function frameCount() {
  const raw = $("#carry-count")?.value ?? "1";
  const n = Number(raw);
  if (!Number.isInteger(n) || n < 1 || n > config.carry_max) {
    throw new Error(`Frames: a whole number from 1 to ${config.carry_max}, not "${raw}"`);
  }
  return n;
}

// Frames one request may carry the page's objects to.
function perRequest() {
  const objects = Math.max(1, doc.instances.length);
  return Math.max(1, Math.min(config.carry_request.frames, Math.floor(config.carry_request.object_frames / objects)));
}

function note(text, kind = "info") {
  const el = $("#carry-note");
  if (!el) return;
  el.textContent = text;
  el.dataset.kind = kind;
  el.hidden = !text;
}

const capital = (text) => text.charAt(0).toUpperCase() + text.slice(1);

// The chain of propagate requests from this frame; returns the last answer
// (null when nothing was carried), with done = frames carried and error = a
// failure after the first request.
async function propagateChain(direction, total, { replace, version }) {
  let url = config.urls.propagate;
  let last = null;
  let done = 0;
  while (done < total) {
    if (total > 1) note(`${WHAT[direction].busy}s… ${done} of ${total} carried`);
    let result;
    try {
      result = await carry(url, { direction, count: Math.min(total - done, perRequest()), replace, version });
    } catch (err) {
      if (!last) throw err;
      return { last, done, error: err };
    }
    last = result;
    done += result.carried.length;
    if (result.stopped) break;
    replace = false; // later frames are never replaced: the server stops before them
    version = null;
    url = config.urls.propagate.replace(`/frames/${config.frame.id}/`, `/frames/${result.frame_id}/`);
  }
  return { last, done, error: null };
}

// kind: "next", "previous" (propagate) or "copy_previous".
async function run(kind, { replace = false, version = null } = {}) {
  const url = kind === "copy_previous" ? config.urls.copy_previous : config.urls.propagate;
  if (reviewing || running || !url) return; // a finished frame may be carried on, not onto
  const button = $(BUTTON[kind]);
  if (button?.disabled) {
    showMessage(button.title, "info"); // the key (Shift+arrow) says why, as the tooltip does
    return;
  }
  let total = 1;
  if (kind !== "copy_previous") {
    try {
      total = frameCount();
    } catch (err) {
      showMessage(err.message, "error");
      return;
    }
  }
  running = true;
  hideBanner();
  try {
    await autosaver.flush();
    if (autosaver.dirty) {
      showMessage("Your changes could not be saved yet; propagation works on the saved annotation. Try again.", "error");
      return;
    }
    showMessage(kind === "copy_previous" ? WHAT[kind].busy : `${WHAT[kind].busy}${total > 1 ? "s" : ""}…`, "info");
    setBusy(1);
    let chain;
    try {
      chain = kind === "copy_previous"
        ? { last: await carry(url, { replace, version }), done: 1, error: null }
        : await propagateChain(kind, total, { replace, version });
    } finally {
      setBusy(-1);
    }
    if (kind === "copy_previous") return await leave(window.location.href);
    const { last, done, error } = chain;
    const numbers = last.carried.length ? `#${last.carried[last.carried.length - 1].index}` : "";
    let text = "";
    let level = "info";
    if (error) {
      text = `Carried to ${done} frame${done === 1 ? "" : "s"} (up to ${numbers}), then: ${errorText(error)}`;
      level = "error";
    } else if (last.stopped) {
      text = `${capital(last.stopped.reason)}.${done > 1 || last.stopped.kind !== "unsure" ? ` Carried to ${done} frame${done === 1 ? "" : "s"}.` : ""}`;
      level = last.stopped.kind === "unsure" ? "warning" : "info";
    } else if (total > 1) {
      text = `Carried to ${done} frames, up to ${numbers}.`;
    }
    if (text) sessionStorage.setItem(NOTE, JSON.stringify({ frame: last.frame_id, text, kind: level }));
    await leave(last.url);
  } catch (err) {
    note("");
    if (err.status === 409 && err.body?.fields?.replace) offerReplace(kind, err);
    else showMessage(errorText(err), "error");
  } finally {
    running = false;
  }
}

function offerReplace(kind, err) {
  const banner = $("#carry-conflict");
  $("#carry-conflict-text").textContent = `${capital(err.message)}. Replace your work on ${WHAT[kind].target} with the carried objects?`;
  $("#message").hidden = true; // the "Propagating…" note: the banner says what happened
  banner.dataset.kind = kind;
  banner.dataset.version = err.body.current_version;
  banner.hidden = false;
}

function hideBanner() {
  $("#carry-conflict").hidden = true;
}

function label() {
  const n = Number($("#carry-count").value);
  const many = Number.isInteger(n) && n > 1;
  $("#propagate-next").textContent = many ? `Propagate to next ${n} frames ⇨` : "Propagate to next frame ⇨";
  $("#propagate-previous").textContent = many ? `⇦ Propagate to previous ${n} frames` : "⇦ Propagate to previous frame";
}

export const propagateNext = () => run("next");
export const propagatePrevious = () => run("previous");

// Propagate and Copy, disabled with the reason as their tooltip when they
// cannot work: no next (previous) frame in the sequence, nothing drawn to carry.
const BUTTON = { next: "#propagate-next", previous: "#propagate-previous", copy_previous: "#copy-previous" };
const nothingDrawn = () => !doc.instances.some((i) => i.mask.includes(1));
const WHY_NOT = {
  "#propagate-next": () =>
    !config.carry?.next ? "This is the sequence's last frame: there is no next frame to propagate to."
      : nothingDrawn() ? "Nothing to propagate yet: draw an object first." : null,
  "#propagate-previous": () =>
    !config.carry?.previous ? "This is the sequence's first frame: there is no previous frame to propagate to."
      : nothingDrawn() ? "Nothing to propagate yet: draw an object first." : null,
  "#copy-previous": () => (!config.carry?.previous ? "This is the sequence's first frame: there is no previous frame to copy from." : null),
};

// Called on every redraw of the objects and by updateLock (label_lock.js), which sets the edit-only controls.
export function updateCarryButtons() {
  for (const [selector, whyNot] of Object.entries(WHY_NOT)) {
    const button = $(selector);
    if (!button) continue;
    button.dataset.title ??= button.title;
    const reason = whyNot();
    button.disabled = reason !== null || (button.classList.contains("edit-only") && !editable); // Copy writes here
    button.title = reason ?? button.dataset.title;
  }
}
export const copyPrevious = () => run("copy_previous");

export function wirePropagate() {
  if (reviewing) return;
  $("#propagate-next")?.addEventListener("click", propagateNext);
  $("#propagate-previous")?.addEventListener("click", propagatePrevious);
  $("#copy-previous")?.addEventListener("click", copyPrevious);
  if ($("#carry-count")) {
    $("#carry-count").addEventListener("input", label);
    label(); // the browser may restore the field's value on reload
  }
  $("#carry-replace").addEventListener("click", () => {
    const banner = $("#carry-conflict");
    run(banner.dataset.kind, { replace: true, version: Number(banner.dataset.version) });
  });
  $("#carry-cancel").addEventListener("click", hideBanner);
  // What the last propagation said about the frame it opened (this one).
  const saved = sessionStorage.getItem(NOTE);
  if (saved) {
    sessionStorage.removeItem(NOTE);
    try {
      const { frame, text, kind } = JSON.parse(saved);
      if (frame === config.frame.id) note(text, kind);
    } catch {
      // a note from an older page: nothing to show
    }
  }
  updateCarryButtons();
  document.addEventListener("label:instances-rendered", updateCarryButtons);
}
