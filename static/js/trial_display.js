// How large the frame is drawn, and whether the window can show the study:
// the study's `display` settings (app.services.studies.protocol) applied to
// the stage (the area between the bar and the buttons) and the window, all
// in CSS pixels. No DOM here, so Node's test runner can check it.

import { fitRect } from "./trial_geometry.js";

// The frame's rectangle in the stage {left, top, width, height, scale, fits}:
// fitted to the stage (default), a fixed `width_px`, or a `fraction` of the
// stage (fitted to that share of it). `fits` is false when a fixed width
// does not fit in the stage: the page then asks for a larger window.
export function displayRect(nativeWidth, nativeHeight, stageWidth, stageHeight, display = {}) {
  if (display.width_px) {
    const width = display.width_px;
    const height = (width * nativeHeight) / nativeWidth;
    return {
      left: (stageWidth - width) / 2,
      top: Math.max(0, (stageHeight - height) / 2),
      width,
      height,
      scale: width / nativeWidth,
      fits: width <= stageWidth + 0.5 && height <= stageHeight + 0.5,
    };
  }
  const share = display.fraction ?? 1;
  const r = fitRect(nativeWidth, nativeHeight, stageWidth * share, stageHeight * share);
  return { ...r, left: (stageWidth - r.width) / 2, top: (stageHeight - r.height) / 2, fits: r.width > 0 };
}

// Why the window cannot show the study now (a sentence), or null: smaller
// than the study's `min_window`, or too small for its fixed frame size.
export function windowProblem(windowWidth, windowHeight, display = {}, rect = null) {
  const min = display.min_window;
  if (min && (windowWidth < min.width || windowHeight < min.height)) {
    return (
      `This study needs a window of at least ${min.width} × ${min.height} pixels; yours is ` +
      `${Math.round(windowWidth)} × ${Math.round(windowHeight)}. Make it larger (or turn your device sideways).`
    );
  }
  if (rect && !rect.fits) {
    return (
      `The photos are shown ${Math.round(rect.width)} × ${Math.round(rect.height)} pixels large and do not fit in ` +
      "your window. Make it larger (or turn your device sideways)."
    );
  }
  return null;
}

// A time in milliseconds to 0.1 ms (the browsers' clocks are coarser; this
// drops the float noise of subtracting two performance.now() readings).
export function roundMs(ms) {
  return Math.round(ms * 10) / 10;
}
