// The heat map's colour bar: what its ticks say on the probability scale or
// stretched to one map's range (the viewer's display-only switch).

// `value` with at most three significant digits, without trailing zeros ("0.0123", "0.5", "1").
export function formatTick(value) {
  if (value === 0) return "0";
  return String(Number(value.toPrecision(3)));
}

// `count` evenly spaced tick labels from `low` to `high`.
export function scaleTicks(low, high, count = 5) {
  const ticks = [];
  for (let i = 0; i < count; i++) ticks.push(formatTick(low + ((high - low) * i) / (count - 1)));
  return ticks;
}
