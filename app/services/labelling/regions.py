"""From a model's probability map to the regions "Suggest" proposes.

Each connected region of the map at or above a threshold is a candidate:
regions smaller than ``MIN_AREA_FRACTION`` of the frame are specks and
dropped, regions over ``MAX_AREA_FRACTION`` mean the map is not selective
there and are dropped too; at most ``MAX_PROPOSALS``, the most probable
first. Each region carries how far GrabCut may move its edge (``_band``).
"""

from dataclasses import dataclass

import cv2
import numpy as np

MIN_AREA_FRACTION = 0.002
"""Regions smaller than this share of the frame are specks, not proposals (154 px at 320x240)."""
MAX_AREA_FRACTION = 0.5
"""A region over half the frame says the map is above the threshold nearly everywhere: no proposal."""
MAX_PROPOSALS = 5
"""At most this many regions per frame, the most probable first (sum of probability over the region)."""
REFINE_BAND = 0.06
"""GrabCut may move a region's edge at least by this share of its long side (and MIN_REFINE_BAND_PX),
further where the map blurs it (``_band``), at most by MAX_REFINE_BAND of it: the map is
blurry at its low resolution, so its edge is near the object's, not on it."""
MIN_REFINE_BAND_PX = 3
MAX_REFINE_BAND = 0.25


@dataclass
class Region:
    """A connected region of the thresholded map: a proposal before GrabCut.

    Attributes:
        mask: bool ``(H, W)``.
        box: The region's box ``(x0, y0, x1, y1)`` (x1, y1 exclusive).
        band: How far GrabCut may move its edge, pixels (``REFINE_BAND``).
        area: Pixels in the region.
        mass: Sum of the probability over the region (how the regions are ranked).
    """

    mask: np.ndarray
    box: tuple[int, int, int, int]
    band: float
    area: int
    mass: float


def proposal_regions(
    probability: np.ndarray,
    threshold: float,
    *,
    min_area_fraction: float = MIN_AREA_FRACTION,
    max_area_fraction: float = MAX_AREA_FRACTION,
    limit: int = MAX_PROPOSALS,
) -> tuple[list[Region], list[str]]:
    """The connected regions of ``probability >= threshold`` worth proposing.

    Args:
        probability: float ``(H, W)`` in [0, 1].
        threshold: Pixels at or above it are the object's.
        min_area_fraction: Smaller regions (a share of the frame) are dropped as specks.
        max_area_fraction: Larger regions are dropped: the map is not selective there.
        limit: At most this many, the largest probability mass first.

    Returns:
        ``(regions, notes)``: the regions, most probable first, and what was
        dropped, in words.

    Example:
        >>> p = np.zeros((40, 60), np.float32); p[10:20, 10:30] = 0.9
        >>> regions, notes = proposal_regions(p, 0.5)
        >>> [(r.area, r.box, r.band) for r in regions], notes
        ([(200, (10, 10, 30, 20), 3.0)], [])
    """
    h, w = probability.shape
    binary = (probability >= threshold).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    min_area = max(1, int(np.ceil(min_area_fraction * h * w)))
    regions, specks, too_large = [], 0, 0
    for label in range(1, count):
        area = int(stats[label, cv2.CC_STAT_AREA])
        if area < min_area:
            specks += 1
            continue
        if area > max_area_fraction * h * w:
            too_large += 1
            continue
        mask = labels == label
        regions.append(_region(mask, probability, stats[label], area))
    regions.sort(key=lambda r: -r.mass)
    notes = []
    if specks:
        notes.append(f"{specks} speck{'' if specks == 1 else 's'} under {min_area} px dropped")
    if too_large:
        notes.append(f"{too_large} region{'' if too_large == 1 else 's'} over {max_area_fraction:.0%} of the frame "
                     "dropped (the map is above the threshold almost everywhere)")
    if len(regions) > limit:
        notes.append(f"{len(regions) - limit} less probable region{'' if len(regions) - limit == 1 else 's'} left out")
        regions = regions[:limit]
    return regions, notes


def _region(mask: np.ndarray, probability: np.ndarray, stat: np.ndarray, area: int) -> Region:
    x, y, bw, bh = (int(v) for v in stat[:4])
    return Region(
        mask=mask,
        box=(x, y, x + bw, y + bh),
        band=_band(mask, probability, max(bw, bh)),
        area=area,
        mass=float(probability[mask].sum()),
    )


def _band(mask: np.ndarray, probability: np.ndarray, size: int) -> float:
    """How far GrabCut may move a region's edge: about as far as the map blurs it.

    The map's rise across the edge (the region's mean probability less that
    of a ring around it) over its slope on the edge is the width of the
    blur: a map at 1/8 of the frame's size blurs an edge over several of
    the frame's pixels, a sharp one over one or two. At least
    ``REFINE_BAND`` of the region's long side (and ``MIN_REFINE_BAND_PX``),
    at most ``MAX_REFINE_BAND`` of it.
    """
    u8 = mask.view(np.uint8)
    edge = cv2.morphologyEx(u8, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)).view(bool)
    reach = max(3, round(MAX_REFINE_BAND * size))
    ring = cv2.dilate(u8, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))).view(bool) & ~mask
    p = probability.astype(np.float32)
    # Sobel's 3x3 weights sum to 8 across a unit ramp: slope per pixel.
    slope = np.hypot(cv2.Sobel(p, cv2.CV_32F, 1, 0), cv2.Sobel(p, cv2.CV_32F, 0, 1))[edge].mean() / 8
    rise = float(p[mask].mean() - (p[ring].mean() if ring.any() else 0.0))
    width = rise / slope if slope > 0 else 0.0
    return float(min(max(width, REFINE_BAND * size, MIN_REFINE_BAND_PX), MAX_REFINE_BAND * size))


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 0.0
