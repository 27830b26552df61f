import assert from "node:assert/strict";
import { test } from "node:test";

import { ActiveClock, Autosaver, indicator, retried, saveText } from "../../static/js/autosave.js";

// A fake clock and timers: run(ms) advances time and fires due timers in order.
function fakeTime() {
  let now = 0;
  let id = 0;
  const timers = new Map();
  return {
    now: () => now,
    timers: {
      setTimeout(fn, ms) {
        timers.set(++id, { at: now + ms, fn });
        return id;
      },
      clearTimeout(t) {
        timers.delete(t);
      },
    },
    async run(ms) {
      const end = now + ms;
      for (;;) {
        const due = [...timers.entries()].filter(([, t]) => t.at <= end).sort((a, b) => a[1].at - b[1].at)[0];
        if (!due) break;
        timers.delete(due[0]);
        now = due[1].at;
        due[1].fn();
        await new Promise((r) => setImmediate(r));
      }
      now = end;
      await new Promise((r) => setImmediate(r));
    },
  };
}

function saver(time, save, extra = {}) {
  const states = [];
  const a = new Autosaver({ save, delay: 500, maxWait: 1500, retryDelay: 3000, timers: time.timers, now: time.now, onState: (s) => states.push(s), ...extra });
  return { a, states };
}

test("a change is saved after a quiet pause", async () => {
  const time = fakeTime();
  const saves = [];
  const { a, states } = saver(time, async () => saves.push(time.now()));
  a.changed();
  await time.run(499);
  assert.equal(saves.length, 0);
  await time.run(1);
  assert.deepEqual(saves, [500]);
  assert.equal(a.dirty, false);
  assert.deepEqual(states, ["pending", "saving", "saved"]);
});

test("steady changes are still saved within maxWait", async () => {
  const time = fakeTime();
  const saves = [];
  const { a } = saver(time, async () => saves.push(time.now()));
  for (let t = 0; t < 4000; t += 100) {
    a.changed();
    await time.run(100);
  }
  assert.equal(saves[0], 1500);
  for (let i = 1; i < saves.length; i++) assert.ok(saves[i] - saves[i - 1] <= 1600, `gap ${saves[i] - saves[i - 1]}`);
});

test("changes made during a save are saved right after it", async () => {
  const time = fakeTime();
  let release;
  const calls = [];
  const { a } = saver(time, () => {
    calls.push(time.now());
    return new Promise((r) => (release = r));
  });
  a.changed();
  await time.run(500);
  assert.equal(calls.length, 1);
  a.changed(); // while saving
  await time.run(2000);
  assert.equal(calls.length, 1, "one save at a time");
  release();
  await time.run(0);
  await time.run(0);
  assert.equal(calls.length, 2);
  assert.equal(a.state, "saving", "the server does not have the last change yet");
  release();
  await time.run(0);
  assert.equal(a.dirty, false);
  assert.equal(a.state, "saved");
});

test("a network failure is retried; a conflict stops until resume", async () => {
  const time = fakeTime();
  let fail = { status: 0 };
  let n = 0;
  const { a, states } = saver(time, async () => {
    n++;
    if (fail) throw fail;
  });
  a.changed();
  await time.run(500);
  assert.equal(a.state, "error");
  await time.run(3000);
  assert.equal(n, 2);
  fail = { status: 409 };
  await time.run(6000);
  assert.equal(a.state, "conflict");
  a.changed();
  await time.run(10000);
  assert.equal(n, 3, "no saving while in conflict");
  fail = null;
  a.resume();
  await time.run(1000);
  assert.equal(n, 4);
  assert.equal(a.state, "saved");
  assert.ok(states.includes("conflict"));
});

test("retries back off, doubling up to the limit, and start again from the first after a success", async () => {
  const time = fakeTime();
  let fail = { status: 0 };
  const tries = [];
  const { a } = saver(time, async () => {
    tries.push(time.now());
    if (fail) throw fail;
  }, { retryDelay: 1000, maxRetryDelay: 5000 });
  a.changed();
  await time.run(500 + 1000 + 2000 + 4000 + 5000 + 5000);
  assert.deepEqual(tries.map((t, i) => t - (tries[i - 1] ?? 0)), [500, 1000, 2000, 4000, 5000, 5000]);
  fail = null;
  await time.run(5000);
  assert.equal(a.state, "saved");
  fail = { status: 503 };
  a.changed();
  await time.run(500);
  assert.equal(a.retryAt, time.now() + 1000, "the first delay again");
});

test("changes made while a retry is due go with that retry, and the last one decides 'saved'", async () => {
  const time = fakeTime();
  let online = false;
  const sent = [];
  let a;
  ({ a } = saver(time, async () => {
    sent.push(a.revision);
    if (!online) throw { status: 0 };
  }));
  const states = [];
  a.onState = (s) => states.push(s);
  a.changed();
  await time.run(500);
  assert.equal(a.state, "error");
  for (let i = 0; i < 10; i++) {
    a.changed();
    await time.run(100);
  }
  assert.deepEqual(sent, [1], "no extra tries between retries");
  assert.equal(a.state, "error", "still says it is not saved");
  online = true;
  await time.run(2000); // the retry, 3 s after the failure
  assert.deepEqual(sent, [1, 11]);
  assert.equal(a.dirty, false);
  assert.deepEqual(states, ["pending", "saving", "error", "saving", "saved"]);
});

test("a refused save is not retried; the next change or a flush tries again", async () => {
  const time = fakeTime();
  let fail = { status: 413, message: "the request body is too large" };
  let n = 0;
  const { a } = saver(time, async () => {
    n++;
    if (fail) throw fail;
  });
  a.changed();
  await time.run(500);
  assert.equal(a.state, "error");
  assert.equal(a.retryAt, null);
  await time.run(60000);
  assert.equal(n, 1);
  assert.equal(saveText(a), "Not saved: the request body is too large");
  a.changed();
  await time.run(500);
  assert.equal(n, 2);
  fail = null;
  await a.flush();
  assert.equal(n, 3);
  assert.equal(a.state, "saved");
});

test("which failures are retried", () => {
  for (const status of [undefined, 0, 401, 408, 429, 500, 502, 503]) assert.ok(retried(status), `${status}`);
  for (const status of [400, 403, 404, 409, 413, 415, 422]) assert.ok(!retried(status), `${status}`);
});

test("the indicator says why a save failed, in words", () => {
  const at = (state, error = null, retryAt = null) => saveText({ state, error, retryAt }, 10_000);
  assert.equal(at("saved"), "All changes saved");
  assert.equal(at("pending"), "Unsaved changes…");
  assert.equal(at("saving"), "Saving…");
  assert.equal(at("conflict"), "Not saved: this frame was saved elsewhere");
  const network = { status: 0, message: "the server could not be reached" };
  assert.equal(at("error", network, 14_200), "Not saved: the server could not be reached; retrying in 5s");
  assert.equal(at("error", network, 10_000), "Not saved: the server could not be reached; retrying in 1s");
  assert.equal(at("error", { status: 500, message: "The server encountered an internal error and was unable…" }, 12_000), "Not saved: the server failed (HTTP 500); retrying in 2s");
  assert.equal(at("error", { status: 401, message: "sign in first" }, 40_000), "Not saved: you are signed out — sign in again in another tab");
  assert.equal(at("error", { status: 403, message: "the participant role cannot use this" }), "Not saved: the participant role cannot use this");
  assert.equal(at("error", { status: 400, message: "instances.0.mask: the size is 10x10, the frame 320x240" }), "Not saved: instances.0.mask: the size is 10x10, the frame 320x240");
  assert.equal(at("error", { status: 400, message: "The CSRF tokens do not match.", body: { error: "csrf" } }), "Not saved: the page's security token was refused; reload the page");
  assert.equal(at("error", new Error("mask is 10x10, the frame 320x240"), 11_000), "Not saved: mask is 10x10, the frame 320x240; retrying in 1s");
});

test("flush saves at once and waits for it; reset forgets", async () => {
  const time = fakeTime();
  let n = 0;
  const { a } = saver(time, async () => n++);
  await a.flush();
  assert.equal(n, 0, "nothing to save");
  a.changed();
  await a.flush();
  assert.equal(n, 1);
  a.changed();
  a.reset();
  await time.run(5000);
  assert.equal(n, 1);
  assert.equal(a.state, "saved");
});

test("the clock counts visible, recently active seconds only", () => {
  let now = 0;
  const clock = new ActiveClock({ idleMs: 10000, now: () => now });
  for (let i = 0; i < 5; i++) {
    now += 1000;
    clock.tick(true);
  }
  assert.equal(clock.pending, 5);
  now += 1000;
  clock.tick(false); // hidden
  now += 20000;
  clock.tick(true); // idle for 26 s
  assert.equal(clock.pending, 5);
  clock.input();
  now += 60000; // a sleeping laptop
  clock.tick(true);
  assert.equal(clock.pending, 5, "idle by then");
  clock.input();
  now += 2000;
  clock.tick(true);
  assert.equal(clock.take(), 7);
  assert.equal(clock.take(), 0);
  clock.giveBack(3);
  assert.equal(clock.take(), 3);
});

test("the indicator never says saved while a step runs or after one was dropped", () => {
  const saved = { state: "saved", error: null, retryAt: null };
  assert.deepEqual(indicator({ saver: saved }), { state: "saved", text: "All changes saved" });
  assert.deepEqual(indicator({ saver: saved, running: 1 }), { state: "saving", text: "Working…" });
  const dropped = { what: "your Object stroke", reason: "the server could not be reached" };
  assert.deepEqual(indicator({ saver: saved, running: 1, dropped }), {
    state: "error",
    text: "Not applied: your Object stroke — the server could not be reached",
  });
  // A failed save speaks first: it is the one that loses the most.
  const failed = { state: "error", error: { status: 0 }, retryAt: null };
  assert.equal(indicator({ saver: failed, dropped }).text, "Not saved: the server could not be reached");
  const finished = { state: "conflict", error: { status: 409, body: { reason: "finished" } }, retryAt: null };
  assert.equal(indicator({ saver: finished }).text, "Not saved: this frame is done and read-only — Edit to change it");
  const conflict = { state: "conflict", error: { status: 409, body: {} }, retryAt: null };
  assert.equal(indicator({ saver: conflict }).text, "Not saved: this frame was saved elsewhere");
});
