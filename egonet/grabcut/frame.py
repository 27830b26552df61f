"""A frame prepared once for the GrabCut sessions that share it.

Building an ROI's low-resolution guides (the scaled ROI and the guided
filter's image terms, the cut's pairwise links, with depth the features and
depth-aware links) costs 5-25 ms on a 1408x1408 frame, as much as a stroke's
cut. A session keeps the guides of its current ROI; a ``GrabCutFrame``
keeps the most recently used ones of every session on the frame, so a
session restored from its state (a server's other process, each request)
and the frame's other objects start from them.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable

import numpy as np

from egonet.errors import EgonetError
from egonet.grabcut.depth import _check_depth, _DepthGuide
from egonet.grabcut.geometry import _Geometry
from egonet.grabcut.refine import _Guide


def _check_image(image: object) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise EgonetError(f"image: expected a numpy array, got {type(image).__name__}", field="image")
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise EgonetError(f"image: expected RGB uint8 of shape (H, W, 3), got {image.dtype} {image.shape}", field="image")
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise EgonetError(f"image: needs at least 2x2 pixels, got {image.shape[1]}x{image.shape[0]}", field="image")
    return np.ascontiguousarray(image).copy()


class GrabCutFrame:
    """One RGB(-D) frame for ``GrabCutSession``s, with the guides they share.

    Args:
        image: RGB uint8 ``(H, W, 3)`` at full resolution (copied, read-only).
        depth: Optional float ``(H, W)`` metres, 0 or NaN where missing
            (copied); sessions on the frame cut with it.
        max_guides: ROIs whose guides are kept, most recently used first.

    Raises:
        ValueError: (``EgonetError``) If ``image`` or ``depth`` is invalid,
            or ``max_guides`` is not an integer >= 1.

    Safe to share between threads: a guide is built once and never changed
    (two threads may build the same one at once; one is kept).

    Example:
        >>> import numpy as np
        >>> from egonet.grabcut import GrabCutSession
        >>> image = np.full((90, 120, 3), 30, np.uint8)
        >>> image[30:60, 40:80] = 220
        >>> frame = GrabCutFrame(image)
        >>> a, b = GrabCutSession(frame), GrabCutSession(frame)
        >>> int(a.box(30, 20, 90, 70).sum()), int(b.box(30, 20, 90, 70).sum()), frame.guides
        (1200, 1200, 1)
    """

    def __init__(self, image: np.ndarray, depth: np.ndarray | None = None, *, max_guides: int = 4) -> None:
        if isinstance(max_guides, bool) or not isinstance(max_guides, (int, np.integer)) or max_guides < 1:
            raise EgonetError(f"max_guides: expected an integer >= 1, got {max_guides!r}", field="max_guides")
        self.image = _check_image(image)
        self.depth = _check_depth(depth, self.image.shape[:2])
        for array in (self.image, self.depth):
            if array is not None:
                array.flags.writeable = False
        self._max = int(max_guides)
        self._cache: OrderedDict[tuple[str, _Geometry], _Guide | _DepthGuide] = OrderedDict()
        self._lock = threading.Lock()

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.image.shape[:2]  # type: ignore[return-value]

    @property
    def guides(self) -> int:
        """How many ROIs' guides are kept now (colour and depth counted apart)."""
        return len(self._cache)

    @property
    def nbytes(self) -> int:
        """Bytes of the frame's copies and the guides kept."""
        with self._lock:
            kept = list(self._cache.values())
        total = self.image.nbytes + (0 if self.depth is None else self.depth.nbytes)
        return total + sum(_guide_bytes(g) for g in kept)

    def guide(self, geom: _Geometry) -> _Guide:
        """The colour guide of ``geom``'s ROI."""
        return self._cached(("colour", geom), lambda: _Guide.build(geom, self.image))  # type: ignore[return-value]

    def depth_guide(self, guide: _Guide) -> _DepthGuide:
        """The depth guide of ``guide``'s ROI (the frame has depth)."""
        return self._cached(("depth", guide.geom),  # type: ignore[return-value]
                            lambda: _DepthGuide.build(guide.geom, guide.image, self.depth))

    def _cached(self, key: tuple[str, _Geometry], build: Callable[[], _Guide | _DepthGuide]) -> _Guide | _DepthGuide:
        with self._lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                return hit
        made = build()  # outside the lock: other threads' sessions go on meanwhile
        with self._lock:
            made = self._cache.setdefault(key, made)
            self._cache.move_to_end(key)
            while len(self._cache) > self._max:
                self._cache.popitem(last=False)
        return made


def _guide_bytes(guide: _Guide | _DepthGuide) -> int:
    if isinstance(guide, _DepthGuide):
        return guide.nbytes
    arrays = [guide.image, guide.colour, guide.mean, guide.inverse,
              *guide.__dict__.get("links", ()), guide.__dict__.get("pixels")]  # made on first use
    return sum(a.nbytes for a in arrays if a is not None)
