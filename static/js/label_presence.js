// Who else is on this frame. The page tells the server it has the frame
// open when it opens it and every heartbeat while it is shown, and that it
// left when it goes; each answer lists the others: people who have the
// frame open, and others' annotations of it. A banner says who and since
// when ("ann has this frame in progress since 14:02"); "Next unlabelled"
// skips such frames on the server.

import { when } from "./label_lock.js";
import { errorText, showMessage } from "./label_panel.js";
import { postPresence } from "./label_server.js";
import { $, config, reviewing } from "./label_state.js";

const STATUS = {
  open: "has this frame open",
  in_progress: "has this frame in progress",
  rejected: "has this frame back from review to fix",
  done: "has labelled this frame (done)",
  reviewed: "has labelled this frame (accepted)",
  todo: "has this frame open",
};
let failing = false;

function ago(iso) {
  const s = Math.max(0, Math.round((Date.now() - new Date(iso).getTime()) / 1000));
  return s < 60 ? "just now" : s < 3600 ? `${Math.round(s / 60)} min ago` : `${Math.round(s / 3600)} h ago`;
}

function describe(other) {
  const last = other.here ? "here now" : `last change ${ago(other.last_seen)}`;
  return `${other.username} ${STATUS[other.status] || STATUS.open} since ${when(other.since)} (${last})`;
}

function show(others) {
  const banner = $("#presence");
  banner.hidden = others.length === 0;
  if (!others.length) return;
  const busy = others.some((o) => o.here || o.status === "in_progress" || o.status === "rejected");
  $("#presence-text").textContent = `${others.map(describe).join("; ")}.`;
  $("#presence-hint").textContent = busy
    ? "Labelling it too makes a second annotation of it: Next unlabelled (U) takes you to a frame nobody holds."
    : "Your annotation would be a second one of this frame.";
}

async function beat() {
  if (document.visibilityState !== "visible") return;
  try {
    show((await postPresence(true)).others);
    failing = false;
  } catch (err) {
    if (!failing) showMessage(`Could not tell who else is on this frame: ${errorText(err)}`, "error");
    failing = true;
  }
}

export function wirePresence() {
  if (reviewing || !config.urls.presence) return;
  beat();
  setInterval(beat, 1000 * (config.heartbeat_s || 30));
  document.addEventListener("visibilitychange", beat);
  window.addEventListener("pagehide", () => postPresence(false, { keepalive: true }).catch(() => {}));
}
