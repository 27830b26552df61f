// The trial page (the practice and the timed part): shows the participant's
// current frame fitted to the window, at a fixed size or a fraction of it
// (the study's display settings), records clicks in native frame pixels
// with their reaction times, and sends the answer. The server decides which
// trial is current and when time is up; this page only counts down what the
// server said. A window below the study's minimum, or one that leaves the
// full screen the study asks for, is covered until it is put right (the
// clock runs on: the server keeps time). The page reports the screen,
// window, pixel ratio and time zone once it loads.
//
// Reaction times are performance.now() milliseconds since the frame was
// painted: the image is decoded first (img.decode()), put on the page, and
// the timestamp of the next animation frame, the one that first shows it,
// is the zero (or, for a photo first seen when the cover is lifted, that
// moment's frame). The next frame is preloaded and decoded while the current
// one is on screen, so it appears as soon as the server answers.

import { api, ApiError } from "./api.js";
import { displayRect, roundMs, windowProblem } from "./trial_display.js";
import { formatClock, toDisplay, toNative } from "./trial_geometry.js";
import { ClickList, keyAction } from "./trial_input.js";

const app = document.getElementById("trial-app");
const multiple = app.dataset.multiple === "true";
const stateUrl = app.dataset.stateUrl;
const practice = app.dataset.phase === "practice";
const display = JSON.parse(app.dataset.display || "{}");
const stage = document.getElementById("stage");
const ui = {
  progressText: document.getElementById("progress-text"),
  progressBar: document.getElementById("progress-bar"),
  timeLeft: document.getElementById("time-left"),
  trialClock: document.getElementById("trial-clock"),
  trialLeft: document.getElementById("trial-left"),
  undo: document.getElementById("undo"),
  none: document.getElementById("none"),
  next: document.getElementById("next"),
  message: document.getElementById("message"),
  blocker: document.getElementById("blocker"),
  blockerText: document.getElementById("blocker-text"),
  fullscreen: document.getElementById("fullscreen"),
};
const markers = document.createElement("div");
markers.className = "markers";

const MAX_EVENTS = 1000;
const images = new Map(); // url -> Promise of a decoded HTMLImageElement

let trial = null; // the trial on screen, as the server described it
let image = null;
let clicks = new ClickList({ multiple });
let events = [];
let paintedAt = null; // performance.now() time base
let sessionEnd = null; // performance.now() when the session's time is up (none in the practice)
let trialEnd = null; // ... and this trial's, when the study has a per-trial limit
let busy = false;
let blocked = false; // the window cannot show the study as it asks (too small, not full screen)

function load(url) {
  if (!images.has(url)) {
    const img = new Image();
    img.alt = "photo";
    img.draggable = false;
    img.src = url;
    const ready = img.decode().then(() => img);
    ready.catch(() => images.delete(url));
    images.set(url, ready);
  }
  return images.get(url);
}

function say(text) {
  ui.message.textContent = text;
}

async function show(state) {
  if (state.redirect) {
    location.assign(state.redirect); // the phase is over (the practice, or the session)
    return;
  }
  const received = performance.now();
  sessionEnd = state.time_left_s == null ? null : received + state.time_left_s * 1000;
  trialEnd = state.trial_time_left_s == null ? null : received + state.trial_time_left_s * 1000;
  if (state.next) load(state.next.image_url).catch(() => {}); // preload; a failure shows when its turn comes
  const shown = state.trial;
  let img;
  try {
    img = await load(shown.image_url);
  } catch {
    say("The photo could not be loaded. Please reload the page.");
    return;
  }
  for (const url of images.keys()) {
    if (url !== shown.image_url && url !== state.next?.image_url) images.delete(url);
  }
  trial = shown;
  image = img;
  image.className = "frame";
  clicks = new ClickList({ multiple });
  events = [];
  paintedAt = null;
  busy = false;
  stage.replaceChildren(image, markers);
  say(state.feedback || "");
  layout();
  ui.progressText.textContent = `${practice ? "Practice" : "Photo"} ${state.done + 1} of ${state.total}`;
  ui.progressBar.max = state.total;
  ui.progressBar.value = state.done;
  ui.trialClock.hidden = trialEnd === null;
  updateButtons();
  tick();
  requestAnimationFrame((timestamp) => {
    if (trial !== shown) return;
    // After a reload the clock goes on from the first showing (the server says how long ago), like server_ms.
    paintedAt = timestamp - (state.shown_ms || 0);
    app.dataset.painted = String(shown.position); // which trial is on screen (tests wait for it)
  });
}

function layout() {
  if (!image || !trial) return;
  const box = stage.getBoundingClientRect();
  const r = displayRect(trial.width, trial.height, box.width, box.height, display);
  for (const el of [image, markers]) {
    Object.assign(el.style, { left: `${r.left}px`, top: `${r.top}px`, width: `${r.width}px`, height: `${r.height}px` });
  }
  drawMarkers();
  check(r);
}

// Cover the stage while the window cannot show the study as it asks.
function check(rect = null) {
  let problem = windowProblem(innerWidth, innerHeight, display, rect);
  // The timed part only (a page change leaves full screen: the practice would ask twice); browsers
  // without the Fullscreen API (an iPhone's) cannot be asked for it.
  const wantsFullscreen = display.fullscreen && !practice && document.fullscreenEnabled && !document.fullscreenElement;
  if (!problem && wantsFullscreen) problem = "This study is done in full screen.";
  const uncovered = blocked && problem === null;
  blocked = problem !== null;
  // A photo first seen when the cover goes: its reaction times count from then.
  if (uncovered && trial && clicks.length === 0) requestAnimationFrame((timestamp) => (paintedAt = timestamp));
  ui.blocker.hidden = !blocked;
  ui.blockerText.textContent = problem || "";
  ui.fullscreen.hidden = !wantsFullscreen;
}

function drawMarkers() {
  const rect = image.getBoundingClientRect();
  markers.replaceChildren(
    ...clicks.items.map((c, i) => {
      const marker = document.createElement("div");
      marker.className = "marker";
      const p = toDisplay(c.x, c.y, rect, trial.width, trial.height);
      marker.style.left = `${p.left}px`;
      marker.style.top = `${p.top}px`;
      if (multiple) marker.textContent = String(i + 1);
      return marker;
    }),
  );
}

function updateButtons() {
  ui.undo.disabled = busy || clicks.length === 0;
  ui.none.disabled = busy || clicks.length > 0;
  ui.none.title = clicks.length > 0 ? "Undo your clicks first" : "";
  if (ui.next) ui.next.disabled = busy || clicks.length === 0;
}

function log(kind, extra = {}) {
  if (events.length >= MAX_EVENTS) return;
  events.push({ kind, t_ms: paintedAt === null ? 0 : roundMs(performance.now() - paintedAt), ...extra });
}

async function refresh() {
  await show(await api("GET", stateUrl));
}

async function submit({ none = false, timedOut = false } = {}) {
  if (busy || !trial) return;
  if (resizeTimer !== null) logResize();
  busy = true;
  updateButtons();
  const rect = image.getBoundingClientRect();
  const body = {
    clicks: none ? [] : clicks.toJSON(),
    none,
    timed_out: timedOut,
    rt_ms: paintedAt === null ? null : roundMs(performance.now() - paintedAt),
    events,
    window: { width: innerWidth, height: innerHeight },
    display: { width: rect.width, height: rect.height },
    pixel_ratio: devicePixelRatio,
  };
  try {
    await show(await api("POST", trial.submit_url, body));
    if (timedOut) say("Time was up for that photo; your clicks so far were kept.");
  } catch (err) {
    busy = false;
    if (err instanceof ApiError && err.status === 409) {
      // The server refused (too late, or already answered): it says where we are.
      await refresh().catch(() => {});
      say(err.message);
    } else {
      say(err instanceof ApiError ? err.message : "Your answer could not be sent. Check the connection and try again.");
      updateButtons();
    }
  }
}

function undo() {
  if (busy) return;
  const removed = clicks.undo();
  if (removed) {
    log("undo", { x: removed.x, y: removed.y });
    drawMarkers();
    updateButtons();
  }
}

function tick() {
  if (sessionEnd === null && trialEnd === null) return;
  const t = performance.now();
  if (sessionEnd !== null) ui.timeLeft.textContent = formatClock((sessionEnd - t) / 1000);
  if (trialEnd !== null) ui.trialLeft.textContent = formatClock((trialEnd - t) / 1000);
  const over = (sessionEnd !== null && t >= sessionEnd) || (trialEnd !== null && t >= trialEnd);
  if (over && !busy && trial) submit({ timedOut: true });
}

stage.addEventListener("pointerdown", (event) => {
  if (event.button !== 0 || busy || blocked || !trial || paintedAt === null) return;
  const p = toNative(event.clientX, event.clientY, image.getBoundingClientRect(), trial.width, trial.height);
  if (!p) return;
  event.preventDefault();
  const x = Math.round(p.x * 100) / 100;
  const y = Math.round(p.y * 100) / 100;
  // An event queued in the very frame that first showed the image can carry
  // a time-stamp a little before that frame's: count it as 0.
  if (!clicks.add(x, y, roundMs(Math.max(0, event.timeStamp - paintedAt)))) {
    say("You have clicked as often as allowed; press Next.");
    return;
  }
  say("");
  drawMarkers();
  updateButtons();
  if (!multiple) submit();
});

ui.undo.addEventListener("click", undo);
ui.none.addEventListener("click", () => submit({ none: true }));
ui.next?.addEventListener("click", () => submit());

document.addEventListener("keydown", (event) => {
  if (event.repeat || event.altKey || event.ctrlKey || event.metaKey || blocked) return;
  const action = keyAction(event.key, { multiple });
  if (!action) return;
  event.preventDefault(); // no button activation or history navigation on top of ours
  if (action === "undo") undo();
  else if (action === "none" && clicks.length === 0) submit({ none: true });
  else if (action === "next" && clicks.length > 0) submit();
});

window.addEventListener("blur", () => log("blur"));
window.addEventListener("focus", () => log("focus"));
document.addEventListener("visibilitychange", () => log("visibility", { state: document.visibilityState }));
// A resize is logged once the window has settled (200 ms), or with the answer if that comes first.
let resizeTimer = null;
function logResize() {
  clearTimeout(resizeTimer);
  resizeTimer = null;
  log("resize", { width: innerWidth, height: innerHeight });
}
window.addEventListener("resize", () => {
  layout();
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(logResize, 200);
});

ui.fullscreen.addEventListener("click", () => {
  document.documentElement.requestFullscreen?.().catch(() => say("Your browser refused full screen; press F11."));
});
document.addEventListener("fullscreenchange", () => {
  log("fullscreen", { state: document.fullscreenElement ? "entered" : "exited" });
  layout();
  check();
});

function reportEnvironment() {
  const body = {
    screen: { width: screen.width, height: screen.height },
    window: { width: innerWidth, height: innerHeight },
    pixel_ratio: devicePixelRatio,
    time_zone: Intl.DateTimeFormat().resolvedOptions().timeZone || null,
    touch: navigator.maxTouchPoints > 0,
  };
  return api("POST", app.dataset.environmentUrl, body).catch(() => {}); // the session goes on without it
}

check();
setInterval(tick, 200);
reportEnvironment();
refresh().catch((err) => say(err instanceof ApiError ? err.message : "The study could not be loaded. Please reload the page."));
