"""A frame prepared once for the GrabCut sessions that share it.

Building an ROI's low-resolution guides (the scaled ROI and the guided
filter's image terms, the cut's pairwise links, with depth the features and
depth-aware links) costs 5-25 ms on a 1408x1408 frame, as much as a stroke's
cut. A session keeps the guides of its current ROI; a ``GrabCutFrame``
keeps the most recently used ones of every session on the frame, so a
session restored from its state (a server's other process, each request)
and the frame's other objects start from them. With a ``GuideStore`` the
guides are shared between processes too: a process that has not seen the
frame's ROI loads them (a few ms) instead of building them.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Mapping
from typing import Protocol

import numpy as np

from egonet.errors import EgonetError
from egonet.grabcut.depth import _FEATURES, _check_depth, _DepthGuide
from egonet.grabcut.geometry import _Geometry
from egonet.grabcut.refine import _Guide

# Part of every stored guide's name: bump it when what a guide holds, or how
# it is computed, changes, so that no process loads an older one.
_GUIDE_FORMAT = 1


class GuideStore(Protocol):
    """Where a frame's guides are shared between processes (the app: files on disk).

    Names are made of letters, digits and ``-``; the store keeps its frames apart.
    """

    def load(self, name: str) -> Mapping[str, np.ndarray] | None:
        """The arrays saved under ``name``, or None."""

    def save(self, name: str, arrays: Mapping[str, np.ndarray]) -> None:
        """Keep ``arrays`` under ``name`` (or not: a store may drop anything)."""


def _check_image(image: object) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise EgonetError(f"image: expected a numpy array, got {type(image).__name__}", field="image")
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise EgonetError(f"image: expected RGB uint8 of shape (H, W, 3), got {image.dtype} {image.shape}", field="image")
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise EgonetError(f"image: needs at least 2x2 pixels, got {image.shape[1]}x{image.shape[0]}", field="image")
    if not image.flags.writeable and image.flags.c_contiguous:
        return image  # read-only already (a memory-mapped file, say): shared as it is
    return np.ascontiguousarray(image).copy()


class GrabCutFrame:
    """One RGB(-D) frame for ``GrabCutSession``s, with the guides they share.

    Args:
        image: RGB uint8 ``(H, W, 3)`` at full resolution: copied, or taken
            as it is if it is read-only already (a memory-mapped file, which
            processes then share).
        depth: Optional float ``(H, W)`` metres, 0 or NaN where missing
            (copied, except a read-only float32 one without zeros); sessions
            on the frame cut with it.
        max_guides: ROIs whose guides are kept, most recently used first.
        store: Optional ``GuideStore`` for this frame: a guide not kept is
            loaded from it before it is built, and ``share`` saves the kept
            ones into it.

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

    def __init__(self, image: np.ndarray, depth: np.ndarray | None = None, *, max_guides: int = 4,
                 store: GuideStore | None = None) -> None:
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
        self._store = store
        self._stored: dict[str, int] = {}  # name -> arrays the store has of it

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

    def share(self) -> int:
        """Save the kept guides into the store that it lacks (or has fewer parts of); how many were saved."""
        if self._store is None:
            return 0
        with self._lock:
            kept = list(self._cache.items())
        saved = 0
        for (kind, geom), guide in kept:
            name, arrays = _name(kind, geom), _arrays(guide)
            if len(arrays) > self._stored.get(name, 0):
                self._store.save(name, arrays)
                self._stored[name] = len(arrays)
                saved += 1
        return saved

    def _cached(self, key: tuple[str, _Geometry], build: Callable[[], _Guide | _DepthGuide]) -> _Guide | _DepthGuide:
        with self._lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                return hit
        made = self._load(*key) or build()  # outside the lock: other threads' sessions go on meanwhile
        with self._lock:
            made = self._cache.setdefault(key, made)
            self._cache.move_to_end(key)
            while len(self._cache) > self._max:
                self._cache.popitem(last=False)
        return made


    def _load(self, kind: str, geom: _Geometry) -> _Guide | _DepthGuide | None:
        """The guide from the store, or None (none there, or not one of this ROI)."""
        if self._store is None:
            return None
        name = _name(kind, geom)
        arrays = self._store.load(name)
        if arrays is None:
            return None
        try:
            guide = _from_arrays(kind, geom, arrays)
        except (KeyError, ValueError):
            return None  # another ROI's or a damaged copy: built again and saved over it
        self._stored[name] = len(arrays)
        return guide


def _name(kind: str, geom: _Geometry) -> str:
    """A guide's name in a store: what it depends on (the ROI and its grid; not the box)."""
    x0, y0, x1, y1 = geom.roi
    return f"v{_GUIDE_FORMAT}-{kind}-{x0}-{y0}-{x1}-{y1}-{geom.low_w}x{geom.low_h}"


def _arrays(guide: _Guide | _DepthGuide) -> dict[str, np.ndarray]:
    """A guide as named arrays (a colour guide's links once it has made them)."""
    if isinstance(guide, _DepthGuide):
        arrays = {"features": guide.features, "valid": guide.valid}
        links = guide.links
    else:
        arrays = {"image": guide.image, "colour": guide.colour, "mean": guide.mean, "inverse": guide.inverse}
        links = guide.__dict__.get("links")
    if links is not None:
        arrays.update(zip(("links_p", "links_q", "links_w"), links))
    return arrays


def _from_arrays(kind: str, geom: _Geometry, arrays: Mapping[str, np.ndarray]) -> _Guide | _DepthGuide:
    """``_arrays``'s inverse for ``geom``, checked (ValueError or KeyError if they do not fit it)."""
    h, w = geom.low_h, geom.low_w

    def take(name: str, dtype: type, shape: tuple[int, ...]) -> np.ndarray:
        array = np.asarray(arrays[name])
        if array.dtype != dtype or array.shape != shape:
            raise ValueError(f"{name}: {array.dtype} {array.shape}, expected {np.dtype(dtype)} {shape}")
        return array

    links = None
    if "links_p" in arrays or kind == "depth":
        p = np.asarray(arrays["links_p"])
        m = (p.shape[0],) if p.ndim == 1 else (-1,)
        p, q = take("links_p", np.int32, m), take("links_q", np.int32, m)
        if p.size and not (0 <= min(p.min(), q.min()) and max(p.max(), q.max()) < h * w):
            raise ValueError("links: pixel indices outside the grid")
        links = (p, q, take("links_w", np.float64, m))
    if kind == "depth":
        return _DepthGuide(geom, take("features", np.float64, (h, w, _FEATURES)), take("valid", np.bool_, (h, w)), links)
    guide = _Guide(geom, take("image", np.uint8, (h, w, 3)), take("colour", np.float32, (h, w, 3)),
                   take("mean", np.float32, (h, w, 3)), take("inverse", np.float32, (h, w, 6)))
    if links is not None:
        guide.__dict__["links"] = links  # what the cached property would have made
    return guide


def _guide_bytes(guide: _Guide | _DepthGuide) -> int:
    if isinstance(guide, _DepthGuide):
        return guide.nbytes
    arrays = [guide.image, guide.colour, guide.mean, guide.inverse,
              *guide.__dict__.get("links", ()), guide.__dict__.get("pixels")]  # made on first use
    return sum(a.nbytes for a in arrays if a is not None)
