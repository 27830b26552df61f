// Frame viewer: the 3-D view of the frame's points (the paper's Fig. 8), drawn on a canvas.
// Drag orbits, the wheel zooms, a double click goes back to the camera's view.
import { decodePoints, initialView, orbit, render, zoom } from "./pointcloud_view.js";

const section = document.getElementById("view3d");
const button = document.getElementById("show-3d");
const panel = document.getElementById("view3d-panel");
const canvas = document.getElementById("view3d-canvas");
const status = document.getElementById("view3d-status");

let points = null;
let start = null;
let view = null;
let pending = false;

function draw() {
  pending = false;
  const context = canvas.getContext("2d");
  const image = context.createImageData(canvas.width, canvas.height);
  const depth = new Float32Array(canvas.width * canvas.height);
  // Squares about as wide as the gaps between neighbouring points seen from the camera.
  const size = Math.max(2, Math.min(6, Math.round(canvas.width / Math.sqrt((points.count * 4) / 3))));
  const drawn = render(points, view, canvas.width, canvas.height, image.data, depth, { size });
  context.putImageData(image, 0, 0);
  canvas.dataset.drawn = String(drawn);
}

function redraw() {
  if (points && !pending) {
    pending = true;
    requestAnimationFrame(draw);
  }
}

async function load() {
  status.textContent = "loading points…";
  const response = await fetch(section.dataset.pointsUrl, { credentials: "same-origin" });
  if (!response.ok) {
    let message = `${response.status}`;
    try {
      message = (await response.json()).message;
    } catch {
      /* an HTML error page: keep the status code */
    }
    throw new Error(message);
  }
  points = decodePoints(await response.arrayBuffer());
  let labelled = 0, predicted = 0;
  for (let i = 0; i < points.count; i++) {
    labelled += points.colors[4 * i + 3] & 1;
    predicted += (points.colors[4 * i + 3] >> 1) & 1;
  }
  const width = Number(section.dataset.width), fx = Number(section.dataset.fx);
  start = initialView(points.positions, width > 0 && fx > 0 ? 2 * Math.atan(width / (2 * fx)) : undefined);
  view = start;
  status.textContent = `${points.count.toLocaleString()} points (${labelled.toLocaleString()} labelled, ${predicted.toLocaleString()} predicted)`;
  canvas.dataset.points = String(points.count);
  redraw();
}

button?.addEventListener("click", async () => {
  const opening = panel.hidden;
  panel.hidden = !opening;
  button.setAttribute("aria-expanded", String(opening));
  if (opening && !points) {
    try {
      await load();
    } catch (error) {
      status.textContent = `Could not load the points: ${error.message}`;
    }
  }
});

let drag = null;
canvas?.addEventListener("pointerdown", (event) => {
  drag = { x: event.clientX, y: event.clientY };
  canvas.setPointerCapture(event.pointerId);
});
canvas?.addEventListener("pointermove", (event) => {
  if (!drag || !view) return;
  view = orbit(view, event.clientX - drag.x, event.clientY - drag.y);
  drag = { x: event.clientX, y: event.clientY };
  redraw();
});
canvas?.addEventListener("pointerup", () => {
  drag = null;
});
canvas?.addEventListener("wheel", (event) => {
  if (!view) return;
  event.preventDefault();
  view = zoom(view, event.deltaY);
  redraw();
}, { passive: false });
canvas?.addEventListener("dblclick", () => {
  view = start;
  redraw();
});
