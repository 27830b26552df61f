// A small SVG line chart: pure layout (ticks, scales, paths) that Node's
// runner tests, and one function that turns the layout into SVG elements.
// No library, no inline style: colours come from the classes series-0..9
// in the page's stylesheet.

const SVG_NS = "http://www.w3.org/2000/svg";
export const PALETTE_SIZE = 10;

// Round, readable tick values covering [min, max] (about `count` of them).
export function niceTicks(min, max, count = 5) {
  if (!Number.isFinite(min) || !Number.isFinite(max)) return [];
  if (max < min) [min, max] = [max, min];
  if (max === min) {
    const pad = Math.abs(min) > 0 ? Math.abs(min) * 0.1 : 1;
    min -= pad;
    max += pad;
  }
  const raw = (max - min) / Math.max(1, count);
  const magnitude = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * magnitude).find((s) => s >= raw) ?? 10 * magnitude;
  const first = Math.floor(min / step + 1e-9);
  const last = Math.ceil(max / step - 1e-9);
  const ticks = [];
  for (let k = first; k <= last && ticks.length <= 50; k += 1) ticks.push(Number((k * step).toFixed(10)));
  return ticks;
}

// Integer ticks for epochs 1..n (at most ~8 labels).
export function epochTicks(maxEpoch) {
  const n = Math.max(1, Math.floor(maxEpoch));
  const step = Math.max(1, Math.ceil(n / 8));
  const ticks = [];
  for (let e = 1; e <= n; e += step) ticks.push(e);
  if (ticks[ticks.length - 1] !== n) ticks.push(n);
  return ticks;
}

export function formatTick(value) {
  if (Math.abs(value) >= 1000 || value === Math.round(value)) return String(Math.round(value));
  const digits = Math.abs(value) >= 1 ? 1 : Math.abs(value) >= 0.1 ? 2 : 3;
  return value.toFixed(digits);
}

function scale(domain0, domain1, range0, range1) {
  const span = domain1 - domain0 || 1;
  return (v) => range0 + ((v - domain0) / span) * (range1 - range0);
}

// The chart as a tree of {tag, attrs, children, text}: axes, grid, one path
// and markers per series, horizontal reference lines.
//
// series: [{label, colour (0..9), dashed, points: [{x, y, note}]}]
// refs:   [{y, label, colour}] drawn as dotted horizontal lines
export function lineChart({ series, refs = [], width = 640, height = 260, xLabel = "", yLabel = "", yMin = null, yMax = null }) {
  const margin = { left: 52, right: 14, top: 12, bottom: 38 };
  const points = series.flatMap((s) => s.points).filter((p) => Number.isFinite(p.y));
  const ys = [...points.map((p) => p.y), ...refs.map((r) => r.y).filter(Number.isFinite)];
  const maxX = Math.max(1, ...points.map((p) => p.x));
  const lo = yMin ?? (ys.length ? Math.min(0, ...ys) : 0);
  const hi = yMax ?? (ys.length ? Math.max(...ys) : 1);
  const yTicks = niceTicks(lo, hi, 5);
  const xTicks = epochTicks(maxX);
  const y0 = yTicks[0];
  const y1 = yTicks[yTicks.length - 1];
  const x = scale(maxX > 1 ? 1 : 0, maxX, margin.left, width - margin.right);
  const y = scale(y0, y1, height - margin.bottom, margin.top);
  const children = [];
  for (const t of yTicks) {
    children.push({ tag: "line", attrs: { class: "grid", x1: margin.left, x2: width - margin.right, y1: y(t), y2: y(t) } });
    children.push({ tag: "text", attrs: { class: "tick", x: margin.left - 6, y: y(t) + 4, "text-anchor": "end" }, text: formatTick(t) });
  }
  for (const t of xTicks) {
    children.push({ tag: "text", attrs: { class: "tick", x: x(t), y: height - margin.bottom + 16, "text-anchor": "middle" }, text: String(t) });
  }
  children.push({ tag: "line", attrs: { class: "axis", x1: margin.left, x2: width - margin.right, y1: height - margin.bottom, y2: height - margin.bottom } });
  children.push({ tag: "line", attrs: { class: "axis", x1: margin.left, x2: margin.left, y1: margin.top, y2: height - margin.bottom } });
  children.push({ tag: "text", attrs: { class: "label", x: (margin.left + width - margin.right) / 2, y: height - 6, "text-anchor": "middle" }, text: xLabel });
  children.push({
    tag: "text",
    attrs: { class: "label", x: 12, y: (margin.top + height - margin.bottom) / 2, "text-anchor": "middle", transform: `rotate(-90 12 ${(margin.top + height - margin.bottom) / 2})` },
    text: yLabel,
  });
  for (const r of refs) {
    if (!Number.isFinite(r.y)) continue;
    children.push({
      tag: "line",
      attrs: { class: `ref series-${r.colour % PALETTE_SIZE}`, x1: margin.left, x2: width - margin.right, y1: y(r.y), y2: y(r.y) },
      children: [{ tag: "title", text: `${r.label}: ${r.y.toFixed(3)}` }],
    });
  }
  for (const s of series) {
    const cls = `series-${s.colour % PALETTE_SIZE}`;
    const drawn = s.points.filter((p) => Number.isFinite(p.y));
    if (!drawn.length) continue;
    const d = drawn.map((p, i) => `${i ? "L" : "M"}${x(p.x).toFixed(1)} ${y(p.y).toFixed(1)}`).join(" ");
    children.push({ tag: "path", attrs: { class: `line ${cls}${s.dashed ? " dashed" : ""}`, d, "data-series": s.label } });
    for (const p of drawn) {
      children.push({
        tag: "circle",
        attrs: { class: `dot ${cls}`, cx: x(p.x).toFixed(1), cy: y(p.y).toFixed(1), r: 2.6 },
        children: [{ tag: "title", text: `${s.label}, epoch ${p.x}: ${p.y.toFixed(4)}${p.note ? ` (${p.note})` : ""}` }],
      });
    }
  }
  return { tag: "svg", attrs: { viewBox: `0 0 ${width} ${height}`, class: "chart-svg", role: "img" }, children };
}

// Replace the children of `svg` (an <svg> element) with the tree's.
export function render(svg, tree) {
  const make = (node) => {
    const el = document.createElementNS(SVG_NS, node.tag);
    for (const [name, value] of Object.entries(node.attrs || {})) el.setAttribute(name, String(value));
    if (node.text !== undefined) el.textContent = node.text;
    for (const child of node.children || []) el.appendChild(make(child));
    return el;
  };
  for (const [name, value] of Object.entries(tree.attrs || {})) svg.setAttribute(name, String(value));
  svg.replaceChildren(...(tree.children || []).map(make));
}
