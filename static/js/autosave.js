// Autosave: every change reaches the server within `maxWait` ms (plus the
// request itself), however steadily the person keeps working, and the page
// is never told "saved" before the server has acknowledged the latest change.
//
// changed() marks the document dirty; a save starts `delay` ms after the
// last change, but never later than `maxWait` ms after the first unsaved
// one. One save runs at a time; changes made meanwhile are saved right
// after it. A failed save, by the answer:
// - none (status 0), 5xx, 401 (signed out: the person can sign in again in
//   another tab), 408, 429: tried again after `retryDelay` ms, doubling up to
//   `maxRetryDelay`; changes made meanwhile go with that retry;
// - 409 (conflict: the page has to ask the person): saving stops until
//   resume() or reset();
// - another 4xx: a retry would fail the same way; the next change or
//   flush() tries again.
//
// States reported through onState: "saved", "pending", "saving", "error",
// "conflict". In "error", `error` is what failed and `retryAt` when the
// next try starts (null: none is due); saveText() puts it in words.

const RETRIED = new Set([0, 401, 408, 429]);

export function retried(status) {
  return !status || RETRIED.has(status) || status >= 500;
}

export class Autosaver {
  constructor({ save, delay = 500, maxWait = 1500, retryDelay = 2000, maxRetryDelay = 30000, timers = globalThis, now = () => Date.now(), onState = () => {} }) {
    this.save = save;
    this.delay = delay;
    this.maxWait = maxWait;
    this.retryDelay = retryDelay;
    this.maxRetryDelay = maxRetryDelay;
    this.timers = timers;
    this.now = now;
    this.onState = onState;
    this.revision = 0; // bumped by every change
    this.savedRevision = 0; // the revision the server has
    this.firstUnsaved = null; // when the oldest change not yet sent was made
    this.timer = null;
    this.inFlight = null;
    this.stopped = false;
    this.state = "saved";
    this.error = null; // the last failure, while not saved since
    this.retryAt = null; // when the next try starts after a failure
    this.failures = 0; // in a row
  }

  get dirty() {
    return this.revision !== this.savedRevision;
  }

  changed() {
    this.revision++;
    if (this.firstUnsaved === null) this.firstUnsaved = this.now();
    // Waiting to retry: the change goes with the retry, at its time.
    if (!this.stopped && this.retryAt === null) this.schedule();
  }

  schedule() {
    this.cancelTimer();
    if (this.inFlight) return; // run() schedules again when the save in flight ends
    const wait = Math.max(0, Math.min(this.delay, (this.firstUnsaved ?? this.now()) + this.maxWait - this.now()));
    this.timer = this.timers.setTimeout(() => this.run(), wait);
    this.setState("pending");
  }

  // Save now (if anything changed), also while waiting to retry; resolves
  // when the server has everything or saving failed.
  async flush() {
    this.cancelTimer();
    if (this.inFlight) await this.inFlight;
    if (this.dirty && !this.stopped) await this.run();
  }

  // Start saving again after a conflict.
  resume() {
    this.stopped = false;
    if (this.dirty) this.schedule();
    else this.setState("saved");
  }

  // Forget unsaved changes (the page replaced its document with the server's).
  reset() {
    this.cancelTimer();
    this.savedRevision = this.revision;
    this.firstUnsaved = null;
    this.stopped = false;
    this.failures = 0;
    this.error = null;
    this.setState("saved");
  }

  run() {
    this.cancelTimer();
    if (this.inFlight || this.stopped || !this.dirty) return this.inFlight || Promise.resolve();
    const revision = this.revision;
    const since = this.firstUnsaved;
    this.firstUnsaved = null;
    this.setState("saving");
    this.inFlight = (async () => {
      try {
        await this.save();
      } catch (error) {
        this.inFlight = null;
        this.firstUnsaved = Math.min(since, this.firstUnsaved ?? since);
        this.failed(error);
        return;
      }
      this.inFlight = null;
      this.failures = 0;
      this.error = null;
      this.savedRevision = Math.max(this.savedRevision, revision);
      if (this.dirty) this.schedule();
      else this.setState("saved");
    })();
    return this.inFlight;
  }

  failed(error) {
    this.error = error;
    if (error?.status === 409) {
      this.stopped = true;
      this.setState("conflict", { always: true });
      return;
    }
    if (retried(error?.status)) {
      const wait = Math.min(this.maxRetryDelay, this.retryDelay * 2 ** this.failures++);
      this.retryAt = this.now() + wait;
      this.timer = this.timers.setTimeout(() => this.run(), wait);
    }
    this.setState("error", { always: true });
  }

  cancelTimer() {
    if (this.timer !== null) this.timers.clearTimeout(this.timer);
    this.timer = null;
    this.retryAt = null;
  }

  setState(state, { always = false } = {}) {
    if (state === this.state && !always) return;
    this.state = state;
    this.onState(state);
  }
}

// The save indicator's words for the saver's state (`now` for the countdown).
export function saveText({ state, error, retryAt }, now = Date.now()) {
  if (state === "saved") return "All changes saved";
  if (state === "pending") return "Unsaved changes…";
  if (state === "saving") return "Saving…";
  if (state === "conflict" && error?.body?.reason === "finished") return "Not saved: this frame is done and read-only — Edit to change it";
  if (state === "conflict") return "Not saved: this frame was saved elsewhere";
  const status = error?.status;
  if (status === 401) return "Not saved: you are signed out — sign in again in another tab";
  let reason = error?.message || "the save failed";
  if (status === 0) reason = "the server could not be reached";
  else if (status >= 500) reason = `the server failed (HTTP ${status})`;
  else if (status === 400 && error.body?.error === "csrf") reason = "the page's security token was refused; reload the page";
  if (retryAt === null || retryAt === undefined) return `Not saved: ${reason}`;
  return `Not saved: ${reason}; retrying in ${Math.max(1, Math.ceil((retryAt - now) / 1000))}s`;
}

// What the page's save indicator says, from the saver and the page's own
// work: a server step under way (`running`, a GrabCut call) is not saved
// yet, and a step that failed (`dropped`: {what, reason}) is not in the
// document at all, so neither may read "All changes saved". A failed or
// refused save says so first. Returns {state, text}.
export function indicator({ saver, running = 0, dropped = null }, now = Date.now()) {
  if (saver.state === "conflict" || saver.state === "error") return { state: saver.state, text: saveText(saver, now) };
  if (dropped) return { state: "error", text: `Not applied: ${dropped.what} — ${dropped.reason}` };
  if (running > 0) return { state: "saving", text: "Working…" };
  return { state: saver.state, text: saveText(saver, now) };
}

// Seconds of active work on a page: counted while the page is visible and
// the person did something within the last `idleMs`.
export class ActiveClock {
  constructor({ idleMs = 60000, now = () => Date.now() } = {}) {
    this.idleMs = idleMs;
    this.now = now;
    this.lastInput = now();
    this.lastTick = now();
    this.pending = 0;
  }

  input() {
    this.lastInput = this.now();
  }

  // Call about once a second; `visible` is whether the page is shown.
  tick(visible) {
    const t = this.now();
    // Clamped: a tab that slept for minutes must not count them.
    const seconds = Math.min(5, Math.max(0, (t - this.lastTick) / 1000));
    this.lastTick = t;
    if (visible && t - this.lastInput <= this.idleMs) this.pending += seconds;
  }

  // The seconds counted since the last take(); giveBack() them if the save fails.
  take() {
    const seconds = this.pending;
    this.pending = 0;
    return seconds;
  }

  giveBack(seconds) {
    this.pending += seconds;
  }
}
