import assert from "node:assert/strict";
import { test } from "node:test";

import { ActiveClock, Autosaver } from "../../static/js/autosave.js";

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
  release();
  await time.run(0);
  assert.equal(a.dirty, false);
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
  await time.run(3000);
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
