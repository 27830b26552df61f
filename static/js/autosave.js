// Autosave: every change reaches the server within `maxWait` ms (plus the
// request itself), however steadily the person keeps working.
//
// changed() marks the document dirty; a save starts `delay` ms after the
// last change, but never later than `maxWait` ms after the first unsaved
// one. One save runs at a time; changes made meanwhile are saved right
// after it. A failed save is retried after `retryDelay` ms, except a 409
// (conflict: the page has to ask the person) and other 4xx answers (a
// retry would fail the same way), which stop saving until resume().
//
// States reported through onState: "saved", "pending", "saving", "error",
// "conflict".

export class Autosaver {
  constructor({ save, delay = 500, maxWait = 1500, retryDelay = 3000, timers = globalThis, now = () => Date.now(), onState = () => {} }) {
    this.save = save;
    this.delay = delay;
    this.maxWait = maxWait;
    this.retryDelay = retryDelay;
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
  }

  get dirty() {
    return this.revision !== this.savedRevision;
  }

  changed() {
    this.revision++;
    if (this.firstUnsaved === null) this.firstUnsaved = this.now();
    if (!this.stopped) this.schedule();
  }

  schedule() {
    this.cancelTimer();
    if (this.inFlight) return; // run() schedules again when the save in flight ends
    const wait = Math.max(0, Math.min(this.delay, (this.firstUnsaved ?? this.now()) + this.maxWait - this.now()));
    this.timer = this.timers.setTimeout(() => this.run(), wait);
    this.setState("pending");
  }

  // Save now (if anything changed); resolves when the server has everything or saving failed.
  async flush() {
    this.cancelTimer();
    if (this.inFlight) await this.inFlight;
    if (this.dirty && !this.stopped) await this.run();
  }

  // Start saving again after a conflict or a refused save.
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
    this.setState("saved");
  }

  run() {
    this.timer = null;
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
        const status = error?.status;
        if (status === 409) {
          this.stopped = true;
          this.setState("conflict");
        } else if (status >= 400 && status < 500) {
          this.stopped = true;
          this.setState("error");
        } else {
          this.setState("error");
          this.timer = this.timers.setTimeout(() => this.run(), this.retryDelay);
        }
        return;
      }
      this.inFlight = null;
      this.savedRevision = Math.max(this.savedRevision, revision);
      if (this.dirty) this.schedule();
      else this.setState("saved");
    })();
    return this.inFlight;
  }

  cancelTimer() {
    if (this.timer !== null) this.timers.clearTimeout(this.timer);
    this.timer = null;
  }

  setState(state) {
    if (state === this.state) return;
    this.state = state;
    this.onState(state);
  }
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
