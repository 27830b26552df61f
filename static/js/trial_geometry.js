// Where the frame is drawn in the window, and how window positions map to
// the frame's native pixels. Native coordinates follow egonet.clicks: x is
// the column, y the row, pixel centres at integers, so the frame spans
// [-0.5, W - 0.5] x [-0.5, H - 0.5].

// The largest rectangle with the frame's aspect ratio that fits in a box,
// centred: {left, top, width, height, scale} in the box's CSS pixels
// (scale = displayed pixels per native pixel).
export function fitRect(nativeWidth, nativeHeight, boxWidth, boxHeight) {
  if (!(nativeWidth > 0 && nativeHeight > 0)) throw new RangeError("the frame size must be positive");
  const scale = Math.max(0, Math.min(boxWidth / nativeWidth, boxHeight / nativeHeight));
  const width = nativeWidth * scale;
  const height = nativeHeight * scale;
  return { left: (boxWidth - width) / 2, top: (boxHeight - height) / 2, width, height, scale };
}

// A point in the window (clientX, clientY) -> native pixel coordinates, or
// null when it falls outside the drawn frame. `rect` is where the frame is
// drawn in the same coordinates (e.g. img.getBoundingClientRect()).
export function toNative(clientX, clientY, rect, nativeWidth, nativeHeight) {
  const u = (clientX - rect.left) / rect.width;
  const v = (clientY - rect.top) / rect.height;
  const edge = 1e-9; // rounding must not push a point on the border outside
  if (!(u >= -edge && u <= 1 + edge && v >= -edge && v <= 1 + edge)) return null;
  return {
    x: clamp(u * nativeWidth - 0.5, -0.5, nativeWidth - 0.5),
    y: clamp(v * nativeHeight - 0.5, -0.5, nativeHeight - 0.5),
  };
}

// Native pixel coordinates -> a point relative to the drawn frame's top-left
// corner (for placing a marker over it).
export function toDisplay(x, y, rect, nativeWidth, nativeHeight) {
  return { left: ((x + 0.5) / nativeWidth) * rect.width, top: ((y + 0.5) / nativeHeight) * rect.height };
}

// Seconds -> "m:ss" (rounded up, so 0:00 means the time is really up).
export function formatClock(seconds) {
  const s = Math.max(0, Math.ceil(seconds));
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, "0")}`;
}

function clamp(value, low, high) {
  return Math.min(high, Math.max(low, value));
}
