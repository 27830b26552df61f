// The filmstrip under the canvas: the sequence's frames as small thumbnails
// coloured by status (todo, in progress, done, reviewed, rejected), the
// current one highlighted; a click opens a frame, "Go to #" opens the frame
// with that number. A sequence may have thousands of frames, so the strip
// holds a window around the current frame and fetches the next window when
// it is scrolled near either end.

import { leave } from "./label_save.js";
import { errorText, showMessage } from "./label_panel.js";
import { getFilmstrip } from "./label_server.js";
import { $, config } from "./label_state.js";

const WINDOW = 41; // frames per request
const EDGE_PX = 240; // scrolled this close to an end, the next window is fetched

const strip = { start: 0, end: 0, total: 0, loading: false };

function tile(frame) {
  const a = document.createElement("a");
  a.className = "film-frame";
  a.href = frame.url;
  a.dataset.id = frame.id;
  a.dataset.status = frame.status;
  a.title = `#${frame.index} · ${frame.status.replace("_", " ")}`;
  if (frame.id === config.frame.id) {
    a.classList.add("current");
    a.setAttribute("aria-current", "page");
  }
  const img = document.createElement("img");
  img.loading = "lazy";
  img.alt = "";
  img.src = frame.thumb_url;
  const number = document.createElement("span");
  number.textContent = frame.index;
  a.append(img, number);
  a.addEventListener("click", (event) => {
    event.preventDefault();
    leave(frame.url);
  });
  return a;
}

// Fetch frames [start, start + count) and put them before or after those shown.
async function extend(start, count, where) {
  if (strip.loading || count <= 0) return;
  strip.loading = true;
  const list = $("#filmstrip-frames");
  try {
    const data = await getFilmstrip({ start, count });
    const tiles = data.frames.map(tile);
    if (where === "before") {
      const width = list.scrollWidth;
      list.prepend(...tiles);
      list.scrollLeft += list.scrollWidth - width; // the frames in view stay in view
      strip.start = data.start;
    } else {
      list.append(...tiles);
      strip.end = data.start + data.frames.length;
    }
    strip.total = data.total;
  } catch (err) {
    showMessage(`Could not load the filmstrip: ${errorText(err)}`, "error");
  } finally {
    strip.loading = false;
  }
}

function onScroll() {
  const list = $("#filmstrip-frames");
  if (list.scrollLeft < EDGE_PX && strip.start > 0) {
    const start = Math.max(0, strip.start - WINDOW);
    extend(start, strip.start - start, "before");
  } else if (list.scrollLeft + list.clientWidth > list.scrollWidth - EDGE_PX && strip.end < strip.total) {
    extend(strip.end, Math.min(WINDOW, strip.total - strip.end), "after");
  }
}

async function jump(event) {
  event.preventDefault();
  const input = $("#jump-to");
  const number = input.valueAsNumber;
  if (!Number.isInteger(number) || number < 0) {
    showMessage("Frame number: give a whole number, 0 or more", "error");
    return;
  }
  try {
    const data = await getFilmstrip({ at: number, count: 1 });
    if (data.focus.id !== config.frame.id) await leave(data.focus.url);
  } catch (err) {
    showMessage(errorText(err), "error");
  }
}

export async function wireFilmstrip() {
  const list = $("#filmstrip-frames");
  if (!list || !config.urls.filmstrip) return;
  $("#jump-form").addEventListener("submit", jump);
  list.addEventListener("scroll", onScroll, { passive: true });
  // A mouse wheel scrolls the strip sideways.
  list.addEventListener(
    "wheel",
    (event) => {
      if (Math.abs(event.deltaY) <= Math.abs(event.deltaX)) return;
      list.scrollLeft += event.deltaY;
      event.preventDefault();
    },
    { passive: false },
  );
  try {
    const data = await getFilmstrip({ count: WINDOW });
    list.replaceChildren(...data.frames.map(tile));
    Object.assign(strip, { start: data.start, end: data.start + data.frames.length, total: data.total });
    $("#filmstrip-where").textContent = `${data.focus.position + 1} of ${data.total} in ${data.sequence}`;
    const current = list.querySelector(".current");
    if (current) list.scrollLeft = current.offsetLeft - (list.clientWidth - current.offsetWidth) / 2;
    list.dataset.ready = "1";
  } catch (err) {
    showMessage(`Could not load the filmstrip: ${errorText(err)}`, "error");
  }
}
