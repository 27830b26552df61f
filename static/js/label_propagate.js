// "Propagate to next frame" (Shift+→) and "Copy from previous frame"
// (Shift+←): the server carries every object of the user's annotation to the
// adjacent frame of the sequence, each mask refined there, and saves it as
// the user's in-progress annotation of that frame. The page saves first (the
// server carries what is saved), then opens the frame that received it.
//
// Existing work is never replaced silently: when the target frame already
// has the user's objects the server answers 409 and the page shows a banner
// that offers "Replace", which sends replace=true with the version the
// server reported (a newer one is refused again); a finished target is
// refused outright.

import { autosaver, leave } from "./label_save.js";
import { errorText, setBusy, showMessage } from "./label_panel.js";
import { carry } from "./label_server.js";
import { $, config, doc, editable, reviewing } from "./label_state.js";

const WHAT = {
  propagate: { busy: "Propagating to the next frame…", target: "the next frame" },
  copy_previous: { busy: "Copying from the previous frame…", target: "this frame" },
};

let running = false;

// kind: "propagate" or "copy_previous".
async function run(kind, { replace = false, version = null } = {}) {
  if (reviewing || running || !config.urls[kind]) return; // a finished frame may be carried on, not onto
  const button = $(kind === "propagate" ? "#propagate-next" : "#copy-previous");
  if (button?.disabled) {
    showMessage(button.title, "info"); // the key (Shift+arrow) says why, as the tooltip does
    return;
  }
  running = true;
  hideBanner();
  try {
    await autosaver.flush();
    if (autosaver.dirty) {
      showMessage("Your changes could not be saved yet; propagation works on the saved annotation. Try again.", "error");
      return;
    }
    showMessage(WHAT[kind].busy, "info");
    setBusy(1);
    let result;
    try {
      result = await carry(kind, { replace, version });
    } finally {
      setBusy(-1);
    }
    await leave(kind === "propagate" ? result.url : window.location.href);
  } catch (err) {
    if (err.status === 409 && err.body?.fields?.replace) offerReplace(kind, err);
    else showMessage(errorText(err), "error");
  } finally {
    running = false;
  }
}

function offerReplace(kind, err) {
  const banner = $("#carry-conflict");
  const reason = err.message.charAt(0).toUpperCase() + err.message.slice(1);
  $("#carry-conflict-text").textContent = `${reason}. Replace your work on ${WHAT[kind].target} with the carried objects?`;
  $("#message").hidden = true; // the "Propagating…" note: the banner says what happened
  banner.dataset.kind = kind;
  banner.dataset.version = err.body.current_version;
  banner.hidden = false;
}

function hideBanner() {
  $("#carry-conflict").hidden = true;
}

// Propagate and Copy, disabled with the reason as their tooltip when they
// cannot work: no next (previous) frame in the sequence, nothing drawn to carry.
const WHY_NOT = {
  "#propagate-next": () =>
    !config.carry?.next ? "This is the sequence's last frame: there is no next frame to propagate to."
      : !doc.instances.some((i) => i.mask.includes(1)) ? "Nothing to propagate yet: draw an object first."
        : null,
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

export const propagateNext = () => run("propagate");
export const copyPrevious = () => run("copy_previous");

export function wirePropagate() {
  if (reviewing) return;
  $("#propagate-next")?.addEventListener("click", propagateNext);
  $("#copy-previous")?.addEventListener("click", copyPrevious);
  $("#carry-replace").addEventListener("click", () => {
    const banner = $("#carry-conflict");
    run(banner.dataset.kind, { replace: true, version: Number(banner.dataset.version) });
  });
  $("#carry-cancel").addEventListener("click", hideBanner);
  updateCarryButtons();
  document.addEventListener("label:instances-rendered", updateCarryButtons);
}
