// The "Use depth" toggle: whether the next GrabCut box cuts with the frame's
// depth. The choice travels with the box request (use_depth); the server's
// session keeps the choice its box was made with, so strokes follow their
// box and a change applies from the next box. A frame without depth has the
// toggle off and disabled (the template says why in its title).

import { $ } from "./label_state.js";

const toggle = $("#use-depth");

// The box request's depth field: {use_depth: true|false}, or nothing when
// the page has no toggle (review mode), which lets the server decide.
export function depthChoice() {
  return toggle ? { use_depth: toggle.checked && !toggle.disabled } : {};
}

// Give the keyboard back to the canvas, so shortcuts (B, Space…) work at once.
toggle?.addEventListener("change", () => toggle.blur());
