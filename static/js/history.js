// A bounded undo / redo stack of entries (whatever the page stores in them).
//
// push(entry) records a change and forgets what could be redone; undo()
// returns the entry to revert, redo() the entry to apply again, or null.
//
// pack() / History.unpack() turn the stack into plain data and back, for
// keeping it across reloads: entries are {before, after, op}, and a state
// shared by two entries (one's `after` is the next one's `before`) is
// written once and shared again when read back.

export class History {
  constructor(limit = 100) {
    if (!(limit >= 1)) throw new Error("limit must be >= 1");
    this.limit = limit;
    this.done = [];
    this.undone = [];
  }

  push(entry) {
    this.done.push(entry);
    if (this.done.length > this.limit) this.done.shift();
    this.undone = [];
  }

  undo() {
    const entry = this.done.pop();
    if (entry === undefined) return null;
    this.undone.push(entry);
    return entry;
  }

  redo() {
    const entry = this.undone.pop();
    if (entry === undefined) return null;
    this.done.push(entry);
    return entry;
  }

  get canUndo() {
    return this.done.length > 0;
  }

  get canRedo() {
    return this.undone.length > 0;
  }

  // The state the last undoable entry left (what the page should show), or null.
  get latest() {
    return this.done.length ? this.done[this.done.length - 1].after : null;
  }

  clear() {
    this.done = [];
    this.undone = [];
  }

  // Take over another history's entries (one read back with unpack()).
  replaceWith(other) {
    this.done = other.done.slice(-this.limit);
    this.undone = other.undone.slice(-this.limit);
  }

  // Forget the oldest undoable entries, keeping `keep` of them.
  trim(keep) {
    this.done = this.done.slice(Math.max(0, this.done.length - keep));
  }

  // Plain data: {states: [...], done: [[before, after, op], ...], undone: [...]},
  // each state once, `toData(state)` making it JSON-able.
  pack(toData = (s) => s) {
    const states = [];
    const index = new Map();
    const ref = (state) => {
      if (!index.has(state)) {
        index.set(state, states.length);
        states.push(toData(state));
      }
      return index.get(state);
    };
    const entry = (e) => [ref(e.before), ref(e.after), e.op ?? null];
    return { states, done: this.done.map(entry), undone: this.undone.map(entry) };
  }

  static unpack(data, { limit = 100, fromData = (s) => s } = {}) {
    if (!data || !Array.isArray(data.states) || !Array.isArray(data.done) || !Array.isArray(data.undone)) {
      throw new Error("not a packed history");
    }
    const states = data.states.map(fromData);
    const state = (k) => {
      if (!Number.isInteger(k) || k < 0 || k >= states.length) throw new Error(`state ${k} is not in the history`);
      return states[k];
    };
    const entry = ([before, after, op]) => ({ before: state(before), after: state(after), op: op ?? null });
    const history = new History(limit);
    history.done = data.done.map(entry).slice(-limit);
    history.undone = data.undone.map(entry).slice(-limit);
    return history;
  }
}
