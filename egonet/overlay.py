"""Pictures of probability maps: one heat map, drawn alone or over its frame.

``heatmap`` is the one renderer: a probability map (H, W) in [0, 1] becomes
turbo colours with an opacity that follows the probability (faint where
unlikely), as RGBA. The frame viewer shows it as a layer over the frame
(a model's prediction); ``overlay`` blends it into the frame itself, with
clicks and an outline (a study's soft masks and their mean).

Example:
    >>> import numpy as np
    >>> layer = heatmap(np.array([[0.0, 1.0]]))
    >>> layer.shape, layer.dtype.name, layer[0, :, 3].tolist()
    ((1, 2, 4), 'uint8', [0, 220])
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from egonet.io import check_rgb

# Full opacity is reached at probability 1 / OPACITY_GAIN and capped at
# MAX_OPACITY, so the frame always shows through a little.
OPACITY_GAIN = 1.4
MAX_OPACITY = 220


def heatmap(probability: np.ndarray) -> np.ndarray:
    """A probability map as turbo colours with a matching opacity.

    Args:
        probability: (H, W) values in [0, 1] (clipped).

    Returns:
        uint8 (H, W, 4) RGBA; alpha is ``min(1, 1.4 p) * 220``.
    """
    p = np.clip(np.asarray(probability, np.float32), 0.0, 1.0)
    rgb = cv2.cvtColor(cv2.applyColorMap(np.round(p * 255).astype(np.uint8), cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    alpha = np.round(np.clip(p * OPACITY_GAIN, 0.0, 1.0) * MAX_OPACITY).astype(np.uint8)
    return np.dstack([rgb, alpha])


def overlay(
    rgb: np.ndarray,
    mask: np.ndarray | None,
    *,
    points: Sequence[tuple[float, float]] = (),
    outline: np.ndarray | None = None,
    max_width: int = 640,
) -> np.ndarray:
    """A frame with a soft mask's heat map blended in, clicks as rings and an optional outline.

    The result is downscaled to at most ``max_width`` pixels wide (never
    upscaled).

    Args:
        rgb: The frame, uint8 (H, W, 3).
        mask: Soft mask in [0, 1], (H, W), or None for the frame alone.
        points: Clicks (x, y) in the frame's pixels, drawn as white rings.
        outline: A binary mask (H, W) whose outer contours are drawn in
            green (for example the ground truth).
        max_width: Widest output in pixels.

    Returns:
        The picture, uint8 (h, w, 3) RGB.

    Example:
        >>> out = overlay(np.zeros((10, 20, 3), np.uint8), np.ones((10, 20), np.float32), max_width=10)
        >>> out.shape, out.dtype.name
        ((5, 10, 3), 'uint8')
    """
    h, w = check_rgb(rgb, "rgb")
    scale = min(1.0, max_width / w)
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    image = rgb.astype(np.float32)
    if scale < 1.0:
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    if mask is not None:
        m = cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_LINEAR) if scale < 1.0 else mask
        layer = heatmap(m).astype(np.float32)
        alpha = layer[..., 3:] / 255.0
        image = image * (1 - alpha) + layer[..., :3] * alpha
    out = np.clip(image, 0, 255).astype(np.uint8)
    if outline is not None:
        edge = cv2.resize(outline.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
        contours, _ = cv2.findContours(edge, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(out, contours, -1, (60, 255, 60), 2, lineType=cv2.LINE_AA)
    for x, y in points:
        centre = (round((x + 0.5) * scale - 0.5), round((y + 0.5) * scale - 0.5))
        cv2.circle(out, centre, 7, (0, 0, 0), 3, lineType=cv2.LINE_AA)
        cv2.circle(out, centre, 7, (255, 255, 255), 2, lineType=cv2.LINE_AA)
    return out
