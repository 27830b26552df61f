// A trial's answer as the participant builds it: clicks with undo, and the
// keyboard shortcuts. No DOM here, so Node's test runner can check it.

export class ClickList {
  // multiple: several clicks allowed (otherwise one click is the answer).
  constructor({ multiple, max = 50 }) {
    this.multiple = multiple;
    this.max = multiple ? max : 1;
    this.items = [];
  }

  get length() {
    return this.items.length;
  }

  // Add a click {x, y} (native pixels) made rtMs after the frame was
  // painted; returns false when no more clicks are taken.
  add(x, y, rtMs) {
    if (this.items.length >= this.max) return false;
    this.items.push({ x, y, rt_ms: rtMs });
    return true;
  }

  // Remove and return the last click (undefined when there is none).
  undo() {
    return this.items.pop();
  }

  toJSON() {
    return this.items.map((c) => ({ ...c }));
  }
}

// A key -> "next" | "none" | "undo" | null. Enter answers only in the
// several-clicks mode (one click answers by itself otherwise).
export function keyAction(key, { multiple }) {
  if (key === "Enter") return multiple ? "next" : null;
  if (key === "n" || key === "N") return "none";
  if (key === "Backspace") return "undo";
  return null;
}
