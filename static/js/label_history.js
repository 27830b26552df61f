// The undo / redo history kept on the server, so Ctrl+Z reaches past a
// reload, a restart (of the server or the browser) and works from another
// browser. After each save the page sends its whole history, packed
// (history.js: each state once, masks as row runs) and gzip-compressed,
// with the annotation version it ends at; on opening the frame it reads it
// back. A history that ends at an older version (the last write was lost
// with the page, or someone saved since) is kept and bridged with one step
// to the loaded document, as "Load theirs" does. Histories too large for the
// server lose their oldest steps first.

import { History } from "./history.js";
import { errorText, showMessage } from "./label_panel.js";
import { getHistory, putHistory } from "./label_server.js";
import { adoptHistory, config, history, meta } from "./label_state.js";

const MAX_BYTES = config.history_max_bytes || 4 * 1024 * 1024;
let lastFailure = null; // say a failure once, not at every save

function toData(state) {
  return {
    ...state,
    instances: state.instances.map((i) => ({ ...i, mask: Array.from(i.mask), engine: i.engine && Array.from(i.engine) })),
  };
}

function fromData(data) {
  return {
    ...data,
    instances: data.instances.map((i) => ({ ...i, mask: Uint32Array.from(i.mask), engine: i.engine && Uint32Array.from(i.engine) })),
  };
}

async function gzip(text) {
  return new Response(new Blob([text]).stream().pipeThrough(new CompressionStream("gzip"))).blob();
}

async function gunzip(blob) {
  return new Response(blob.stream().pipeThrough(new DecompressionStream("gzip"))).text();
}

// Read the stored history back, in place of the page's (after the annotation is loaded).
export async function loadHistory() {
  if (!meta.historyUrl) return;
  try {
    const stored = await getHistory(meta.historyUrl);
    if (!stored) return;
    const data = JSON.parse(await gunzip(stored.blob));
    adoptHistory(History.unpack(data, { limit: history.limit, fromData }), { current: stored.version === meta.version });
  } catch (err) {
    showMessage(`Your undo history could not be read back (${errorText(err)}); undo starts from here.`, "error");
  }
}

// Send the history as it stands at the annotation's current version.
export async function keepHistory({ keepalive = false } = {}) {
  if (!meta.historyUrl) return;
  try {
    let blob = await gzip(JSON.stringify(history.pack(toData)));
    while (blob.size > MAX_BYTES && history.done.length > 1) {
      history.trim(Math.floor(history.done.length / 2)); // the oldest steps go first
      blob = await gzip(JSON.stringify(history.pack(toData)));
    }
    await putHistory(meta.historyUrl, meta.version, blob, { keepalive });
    lastFailure = null;
  } catch (err) {
    if (err.status === 409) return; // saved again meanwhile (another tab): that save sends its own
    const text = errorText(err);
    if (text !== lastFailure) showMessage(`Your undo history could not be kept on the server (${text}); undo still works on this page.`, "error");
    lastFailure = text;
  }
}
