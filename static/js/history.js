// A bounded undo / redo stack of entries (whatever the page stores in them).
//
// push(entry) records a change and forgets what could be redone; undo()
// returns the entry to revert, redo() the entry to apply again, or null.

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

  clear() {
    this.done = [];
    this.undone = [];
  }
}
