"""The interactive session: a box, corrective strokes, undo, and its state.

``GrabCutSession`` keeps the undo levels (``state._Snapshot``) and the
current full-resolution mask, and composes the parts: the geometry of the
box's ROI (``geometry``), the graph cut at the work size (``cut``, with the
colour models of ``colour``, or with a depth map the colour-plus-depth models
of ``depth``), the refinement back to full resolution
(``refine``) and the strokes as hard constraints (``strokes``).
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.grabcut.colour import _first_models
from egonet.grabcut.cut import (_LINE_MIDDLE, _NEAR_GRID, _STROKE_REACH, _box_cut, _box_labels, _depth_box_cut,
                               _depth_first_models, _keep_connected, _recut, _seed_cut, _Terms)
from egonet.grabcut.depth import _DepthGuide
from egonet.grabcut.fine import _THIN, _fine_cut
from egonet.grabcut.frame import GrabCutFrame
from egonet.grabcut.geometry import _clip_to_box, _downsample, _Geometry, _grow_box
from egonet.grabcut.refine import _BAND, _GF_RADIUS, _Guide, _upsample_mask
from egonet.grabcut.state import STATE_FORMAT, _decode_levels, _encode_state, _Snapshot, _unpack
from egonet.grabcut.strokes import LABELS, _check_points, _check_radius, _polyline_distance_mask, _Stroke


def _frame_of(image: object, depth: object) -> tuple[GrabCutFrame, bool]:
    """The session's frame and whether it is shared (given), or one of its own."""
    if isinstance(image, GrabCutFrame):
        if depth is not None:
            raise EgonetError("depth: a GrabCutFrame holds the frame's depth; give it to GrabCutFrame, not here",
                              field="depth")
        return image, True
    return GrabCutFrame(image, depth, max_guides=2), False


def _check_seed(mask: object, shape: tuple[int, int]) -> np.ndarray:
    if not isinstance(mask, np.ndarray):
        raise EgonetError(f"mask: expected a numpy array, got {type(mask).__name__}", field="mask")
    if mask.shape != tuple(shape) or not (mask.dtype == bool or np.issubdtype(mask.dtype, np.integer)):
        raise EgonetError(f"mask: expected a bool (H, W) = {tuple(shape)} array, got {mask.dtype} {mask.shape}",
                          field="mask")
    if mask.dtype != bool:
        if ((mask != 0) & (mask != 1)).any():
            raise EgonetError("mask: integer masks must hold only 0 and 1", field="mask")
        mask = mask != 0
    if not mask.any():
        raise EgonetError("mask: is empty; there is no object to start from (draw a box)", field="mask")
    return mask


def _as_int(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise EgonetError(f"{name}: expected a number, got {value!r}", field=name)
    if not math.isfinite(float(value)):
        raise EgonetError(f"{name}: must be finite, got {value!r}", field=name)
    return int(round(float(value)))


class GrabCutSession:
    """Interactive GrabCut segmentation of one object in one RGB(-D) frame.

    Args:
        image: RGB uint8 ``(H, W, 3)`` frame at full resolution (copied), or
            a :class:`~egonet.grabcut.frame.GrabCutFrame` that sessions of the
            frame share (with its depth, if any: then ``depth`` stays None).
        depth: Optional float ``(H, W)`` depth of the same frame in metres,
            0 or NaN where missing (copied). With depth the cut models colour
            and depth together and prefers to cut where depth jumps (see
            :mod:`~egonet.grabcut.depth`); pixels without depth are judged by
            colour alone. Without it the session is plain colour GrabCut.
        work_size: Long side, in pixels, of the region of interest when the
            graph cut runs (smaller is faster, coarser before refinement).
        max_undo: Undo levels kept (and serialised by ``state``).

    Raises:
        ValueError: (``EgonetError``) If ``image`` is not RGB uint8
            ``(H, W, 3)``, ``depth`` is not metres of the image's size, or a
            setting is out of range.

    Example:
        >>> import numpy as np
        >>> image = np.full((90, 120, 3), 30, np.uint8)
        >>> image[30:60, 40:80] = 220
        >>> s = GrabCutSession(image)
        >>> int(s.box(30, 20, 90, 70).sum())
        1200
    """

    def __init__(self, image: np.ndarray | GrabCutFrame, depth: np.ndarray | None = None, *, work_size: int = 272,
                 max_undo: int = 20) -> None:
        self._setup(*_frame_of(image, depth), work_size, max_undo)

    def _setup(self, frame: GrabCutFrame, shared: bool, work_size: int, max_undo: int) -> None:
        """``__init__`` on a frame (``shared``: given by the caller, not made for this session)."""
        if isinstance(work_size, bool) or not isinstance(work_size, (int, np.integer)) or work_size < 32:
            raise EgonetError(f"work_size: expected an integer >= 32, got {work_size!r}", field="work_size")
        if isinstance(max_undo, bool) or not isinstance(max_undo, (int, np.integer)) or max_undo < 0:
            raise EgonetError(f"max_undo: expected an integer >= 0, got {max_undo!r}", field="max_undo")
        self._frame, self._shared = frame, shared
        self._image = frame.image
        self._depth = frame.depth
        self._work_size = int(work_size)
        self._max_undo = int(max_undo)
        self._history: list[_Snapshot] = []
        self._now = _Snapshot()
        self._mask = np.zeros(self._image.shape[:2], bool)
        self._guide: _Guide | None = None  # the current ROI's (the frame keeps others)
        # Full-resolution stroke footprints: (crop, origin), per stroke.
        self._footprints: weakref.WeakKeyDictionary[_Stroke, tuple[np.ndarray, tuple[int, int]] | None] = (
            weakref.WeakKeyDictionary())

    # ---------------------------------------------------------------- public

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the frame."""
        return self._mask.shape  # type: ignore[return-value]

    @property
    def mask(self) -> np.ndarray:
        """The current bool ``(H, W)`` mask (a copy)."""
        return self._mask.copy()

    @property
    def box_coords(self) -> tuple[int, int, int, int] | None:
        """The current box ``(x0, y0, x1, y1)``, or None before ``box``."""
        return self._now.box

    @property
    def uses_depth(self) -> bool:
        """Whether the session was given a depth map (and cuts with it)."""
        return self._depth is not None

    @property
    def can_undo(self) -> bool:
        """Whether ``undo`` has a previous state to restore."""
        return bool(self._history)

    @property
    def strokes(self) -> list[tuple[np.ndarray, str, float]]:
        """The current object's strokes since its box, oldest first: ``(points (K, 2), label, radius)``."""
        return [(s.points.copy(), "fg" if s.fg else "bg", s.radius) for s in self._now.strokes]

    @property
    def nbytes(self) -> int:
        """Bytes held in the session's arrays: the mask, the undo levels and
        the cached stroke footprints, and unless the frame was given as a
        shared ``GrabCutFrame``, the frame's copy and its ROIs' guides (with
        the cut's links)."""
        arrays = [self._mask]
        for snap in self._history + [self._now]:
            arrays += [snap.models, snap.low, snap.mask_bits] + [s.points for s in snap.strokes]
        arrays += [hit[0] for hit in self._footprints.values() if hit is not None]
        unique = {id(a): a.nbytes for a in arrays if a is not None}  # undo levels share their strokes
        return sum(unique.values()) + (0 if self._shared else self._frame.nbytes)

    def box(self, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
        """Start a new object from a box and return its first mask.

        Clears the strokes and colour models of the previous object (``undo``
        brings them back). Coordinates are rounded to whole pixels.

        Args:
            x0: Left column (inclusive).
            y0: Top row (inclusive).
            x1: Right column (exclusive), ``x0 < x1 <= W``.
            y1: Bottom row (exclusive), ``y0 < y1 <= H``.

        Returns:
            Bool ``(H, W)`` mask; nothing outside the box is selected.

        Raises:
            ValueError: If the box is empty or not inside the frame (clip it
                to the frame first), or leaves no background around it.
        """
        h, w = self.shape
        bx0, by0 = _as_int(x0, "x0"), _as_int(y0, "y0")
        bx1, by1 = _as_int(x1, "x1"), _as_int(y1, "y1")
        if not (0 <= bx0 < bx1 <= w and 0 <= by0 < by1 <= h):
            raise EgonetError(
                f"box: ({bx0}, {by0}, {bx1}, {by1}) must satisfy 0 <= x0 < x1 <= {w} and "
                f"0 <= y0 < y1 <= {h} (clip it to the {w}x{h} frame and keep it non-empty)", field="box"
            )
        box = (bx0, by0, bx1, by1)
        guide = self._guide_for(box)
        gc = _box_labels(guide.geom)
        if not (gc == cv2.GC_BGD).any():
            raise EgonetError("box: leaves no background in the frame around it; draw a tighter box", field="box")
        line = None
        if self._depth is None:
            low, models, line = _box_cut(self._image, guide, gc, self._work_size)
        else:
            low, models = _depth_box_cut(self._image, self._depth, self._depth_guide_for(guide), gc)
        if line is not None:
            # A long thin straight object across the box (``cut._straight``): followed at full resolution from
            # the line's middle, as a stroke of a grid pixel's width along it would be (``fine``), only in the
            # box (the line's middle is half of it, so the box lies within a quarter of its long side).
            radius = 1 / min(guide.geom.sx, guide.geom.sy)
            reach = math.ceil((1 - _LINE_MIDDLE) / 2 * max(bx1 - bx0, by1 - by0))
            hit = _polyline_distance_mask(self.shape, line, radius)
            if hit is not None:
                mask = np.zeros(self.shape, bool)
                crop, (y0, x0) = hit
                mask[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]] = crop
                thin = _fine_cut(self._image, mask, crop, (y0, x0), True, radius, reach, thin=True)
                if thin is not None and thin.any():
                    mask |= thin
                    _clip_to_box(mask, box)
                    snap = _Snapshot(box=box, strokes=(), models=models, low=_downsample(mask, guide.geom))
                    self._commit(guide, snap, mask)
                    return self.mask
        snap = _Snapshot(box=box, strokes=(), models=models, low=low)
        self._commit(guide, snap, self._full_mask(guide, snap))
        return self.mask

    def seed_mask(self, mask: np.ndarray, *, band: float = 0) -> np.ndarray:
        """Start a new object from a mask (a propagated one, a model's proposal) and return its first mask.

        Like ``box``, it clears the strokes and models of the previous object
        (``undo`` brings them back), and strokes correct the new one at once:
        the object's box is the mask's bounds plus ``band`` and 2 pixels, and
        its models are learnt from the mask, so a stroke re-cuts as it would
        after a box. With ``band`` 0 the mask is kept exactly; with ``band``
        > 0 GrabCut refines it first, moving its edge by at most ``band``
        pixels (the mask eroded by ``band`` stays in, what lies beyond it
        dilated by ``band`` stays out), so a mask that is roughly right (a
        blurry prediction, a mask carried from the previous frame) snaps to
        the object's edges without straying far from it.

        Args:
            mask: Bool (or 0/1 integer) ``(H, W)``, the object; not empty,
                and leaving some of the frame out.
            band: How far refinement may move the mask's edge, pixels (0:
                keep the mask as it is).

        Returns:
            Bool ``(H, W)`` mask.

        Raises:
            ValueError: If ``mask`` is not ``(H, W)`` bool or 0/1, is empty or
                covers the frame, or ``band`` is negative.

        Example:
            >>> import numpy as np
            >>> image = np.full((90, 120, 3), 30, np.uint8)
            >>> image[30:60, 40:80] = 220
            >>> rough = np.zeros((90, 120), bool)
            >>> rough[33:57, 44:76] = True  # a little inside the object
            >>> s = GrabCutSession(image)
            >>> int(s.seed_mask(rough).sum()), int(s.seed_mask(rough, band=6).sum())
            (768, 1200)
            >>> bool(s.stroke([(60, 45)], "bg", 3)[45, 60])
            False
        """
        m = _check_seed(mask, self.shape)
        if isinstance(band, bool) or not isinstance(band, (int, float, np.integer, np.floating)) or not (
                math.isfinite(float(band)) and band >= 0):
            raise EgonetError(f"band: expected a number of pixels >= 0, got {band!r}", field="band")
        h, w = self.shape
        rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
        pad = math.ceil(float(band)) + 2
        box = (max(0, int(cols[0]) - pad), max(0, int(rows[0]) - pad), min(w, int(cols[-1]) + 1 + pad),
               min(h, int(rows[-1]) + 1 + pad))
        guide = self._guide_for(box)
        geom = guide.geom
        rx0, ry0, rx1, ry1 = geom.roi
        share = cv2.resize(m[ry0:ry1, rx0:rx1].astype(np.float32), (geom.low_w, geom.low_h),
                           interpolation=cv2.INTER_AREA)
        # A part smaller than a grid pixel still gives the models a sample.
        seed = share > 0.5 if (share > 0.5).any() else share > 0
        if seed.all():
            raise EgonetError("mask: covers the whole frame; leave some background, or draw a box", field="mask")
        band_low = round(float(band) * 0.5 * (geom.sx + geom.sy))
        if band > 0:
            band_low = max(1, band_low)
        rng = np.random.default_rng(0)
        if self._depth is None:
            terms = _Terms.colour(guide)
            first = lambda sides: _first_models(guide.image, sides, rng)  # noqa: E731
        else:
            depth_guide = self._depth_guide_for(guide)
            terms = _Terms.depth(depth_guide)
            first = lambda sides: _depth_first_models(depth_guide, sides, rng)  # noqa: E731
        low, models = _seed_cut(terms, geom, seed, band_low, first)
        snap = _Snapshot(box=box, strokes=(), models=models, low=low)
        self._commit(guide, snap, m.copy() if band_low == 0 else self._full_mask(guide, snap))
        return self.mask

    def stroke(self, points: Sequence[Sequence[float]] | np.ndarray, label: str, radius: float) -> np.ndarray:
        """Add a corrective brush stroke and return the updated mask.

        Pixels under a ``"fg"`` stroke are in the returned mask, pixels under a
        ``"bg"`` stroke are out, exactly (later strokes win where strokes
        overlap). The colour models are re-estimated with the stroke, so
        similar pixels near it can follow it, but only in the stroke's
        direction: a foreground stroke never removes pixels
        from the mask and a background stroke never adds any. And its effect
        is local: a pixel changes only if it lies near the stroke (two grid
        pixels of the cut, a few frame pixels) or is joined to it through
        pixels that changed too; every other pixel keeps its label. (Without
        those rules, re-estimating the models can drop an unrelated part far
        from the stroke, such as the far end of a thin handle.) A stroke
        narrower than the cut's grid resolves, drawn on a thin part of its
        colour (a chopstick, a tine), is cut at full resolution along that
        part instead (see :mod:`~egonet.grabcut.fine`). A foreground
        stroke that reaches outside the box grows the box to take it in.

        Args:
            points: ``(x, y)`` pixel coordinates of the polyline, at least one
                (one point paints a disk).
            label: ``"fg"`` (object) or ``"bg"`` (background).
            radius: Brush radius in pixels, > 0.

        Returns:
            Bool ``(H, W)`` mask.

        Raises:
            ValueError: If there is no box yet, or ``points``, ``label`` or
                ``radius`` is invalid, or the stroke misses the frame.
        """
        prev = self._now
        if prev.box is None:
            raise EgonetError("box: stroke() needs an object first; call box(x0, y0, x1, y1)", field="box")
        pts = _check_points(points)
        if label not in LABELS:
            raise EgonetError(f"label: expected one of {LABELS}, got {label!r}", field="label")
        r = _check_radius(radius)
        footprint = _polyline_distance_mask(self.shape, pts, r)
        if footprint is None:
            raise EgonetError(f"points: the stroke covers no pixel of the {self.shape[1]}x{self.shape[0]} frame", field="points")
        new = _Stroke(pts, label == "fg", r)
        self._footprints[new] = footprint
        strokes = prev.strokes + (new,)
        box = _grow_box(prev.box, *footprint, r, self.shape) if new.fg else prev.box
        guide = self._guide_for(box)
        new_roi = box != prev.box
        # In a new ROI the cut starts from the current mask (the models carry over either way).
        prior = _downsample(self._mask, guide.geom) if new_roi else prev.low
        # A stroke thinner than the grid resolves, on a thin part of its colour, is cut at full resolution
        # along that part (``fine``); the grid's label follows.
        thin = None
        if self._depth is None and r * min(guide.geom.sx, guide.geom.sy) < _THIN:
            mask = self._mask.copy()
            self._apply_strokes(mask, (new,))
            thin = _fine_cut(self._image, mask, *footprint, new.fg, r)
        if thin is not None:
            mask[thin] = new.fg
            _clip_to_box(mask, box)
            self._apply_strokes(mask, strokes)
            moved = _downsample(mask != self._mask, guide.geom)
            snap = _Snapshot(box=box, strokes=strokes, models=prev.models,
                             low=(prior | moved) if new.fg else (prior & ~moved))
        else:
            if self._depth is None:
                low, models = _recut(_Terms.colour(guide), guide, prev.models, strokes, prior, flood=True)
            else:
                low, models = _recut(_Terms.depth(self._depth_guide_for(guide)), guide, prev.models, strokes, prior,
                                     reach=None)
            snap = _Snapshot(box=box, strokes=strokes, models=models, low=low)
            if new_roi:
                # Both masks honour every stroke, so their union does too.
                mask = self._mask | self._full_mask(guide, snap)
            else:
                mask = self._refresh_changed(guide, snap, prev.low, new.fg)
                self._apply_strokes(mask, strokes)
        # Local at full resolution too: only what is joined to the stroke through the change moves.
        grid = min(guide.geom.sx, guide.geom.sy)
        mask = _keep_connected(mask, self._mask, *footprint, math.ceil(_NEAR_GRID / grid),
                               None if self._depth is not None else math.ceil(_STROKE_REACH / grid))
        self._commit(guide, snap, mask)
        return self.mask

    def undo(self) -> np.ndarray:
        """Restore the previous mask and state, and return the mask.

        Raises:
            RuntimeError: If there is nothing to undo (see ``can_undo``).
        """
        if not self._history:
            raise RuntimeError("undo: nothing to undo")
        self._restore(self._history.pop())
        return self.mask

    def state(self) -> dict[str, np.ndarray | int | float | str]:
        """A small, serialisable description of the session (undo levels too).

        Every value is a numpy array, int, float or str, so the dict can go
        through ``np.savez`` (or a database blob) and back into
        ``from_state``. The image itself is not included.

        Returns:
            Dict with ``format``, the frame size, the settings, and per undo
            level (oldest first, the current one last) the box, the strokes,
            the two colour models (OpenCV grabCut's bgdModel/fgdModel layout,
            ``(2, 65)``; with depth the ``(2, 105)`` colour-plus-depth models
            of :mod:`~egonet.grabcut.depth` and ``uses_depth`` = 1),
            the low-resolution cut (packed bits) and the mask inside the box
            (run lengths, row-major, starting with a background run).
        """
        return _encode_state(self._history + [self._now], height=int(self.shape[0]), width=int(self.shape[1]),
                             work_size=self._work_size, max_undo=self._max_undo, uses_depth=self.uses_depth)

    @classmethod
    def from_state(cls, image: np.ndarray | GrabCutFrame, state: Mapping[str, object],
                   depth: np.ndarray | None = None) -> GrabCutSession:
        """Resume a session from ``state()`` and the same image (and depth).

        The state holds neither the image nor the depth: they are the frame's,
        so the caller passes them again. A session made with depth resumes
        only with depth, one made without only without.

        Args:
            image: The RGB uint8 ``(H, W, 3)`` frame the state was made on,
                or a shared ``GrabCutFrame`` of it (holding its depth, if the
                session was made with depth).
            state: A dict from ``state()``, possibly after ``np.savez`` and
                ``np.load`` (0-d arrays are accepted for the scalars).
            depth: The frame's depth in metres ``(H, W)`` if the session was
                made with depth (``state["uses_depth"]``), else None.

        Returns:
            A session that continues exactly where the saved one stopped,
            undo levels included.

        Raises:
            ValueError: (``EgonetError``) If ``image`` or ``depth`` is
                invalid, ``depth`` is missing for a state made with depth (or
                given for one made without), or ``state`` is malformed or was
                made on a frame of another size.

        Example:
            >>> import numpy as np
            >>> image = np.full((90, 120, 3), 30, np.uint8)
            >>> image[30:60, 40:80] = 220
            >>> s = GrabCutSession(image)
            >>> _ = s.box(30, 20, 90, 70)
            >>> t = GrabCutSession.from_state(image, s.state())
            >>> bool((t.stroke([(50, 40)], "bg", 4) == s.stroke([(50, 40)], "bg", 4)).all())
            True
        """
        frame, shared = _frame_of(image, depth)
        if not isinstance(state, Mapping):
            raise EgonetError(f"state: expected the dict from GrabCutSession.state(), got {type(state).__name__}", field="state")
        try:
            return cls._from_state(frame, shared, state)
        except (KeyError, IndexError, TypeError, ValueError) as exc:
            if isinstance(exc, EgonetError) and exc.field in ("state", "depth"):
                raise
            raise EgonetError(f"state: malformed GrabCut session state ({type(exc).__name__}: {exc})", field="state") from exc

    @classmethod
    def _from_state(cls, frame: GrabCutFrame, shared: bool, state: Mapping[str, object]) -> GrabCutSession:
        def scalar(key: str) -> object:
            return np.asarray(state[key]).item()

        if scalar("format") != STATE_FORMAT:
            raise EgonetError(f"state: format {scalar('format')!r} is not {STATE_FORMAT!r}", field="state")
        uses_depth = bool(np.asarray(state.get("uses_depth", 0)).item())
        if uses_depth != (frame.depth is not None):
            raise EgonetError("depth: this state was made " + (
                "with depth; pass the frame's depth (H, W) in metres" if uses_depth else
                "without depth; resume it without depth (or start a new session with depth)"), field="depth")
        session = cls.__new__(cls)
        session._setup(frame, shared, int(scalar("work_size")), int(scalar("max_undo")))
        h, w = session.shape
        if (int(scalar("height")), int(scalar("width"))) != (h, w):
            raise EgonetError(f"state: made on a {scalar('width')}x{scalar('height')} frame, the image is {w}x{h}", field="state")
        levels = _decode_levels(state, h, w, uses_depth=uses_depth)
        session._history = levels[:-1]
        session._restore(levels[-1])
        return session

    # --------------------------------------------------------------- helpers

    def _guide_for(self, box: tuple[int, int, int, int]) -> _Guide:
        """The low-resolution guide of ``box``'s ROI (cached for the current one)."""
        geom = _Geometry.for_box(box, *self.shape, self._work_size)
        if self._guide is not None and self._guide.geom == geom:
            return self._guide
        return self._frame.guide(geom)

    def _depth_guide_for(self, guide: _Guide) -> _DepthGuide:
        """The depth guide of ``guide``'s ROI (the frame keeps it)."""
        return self._frame.depth_guide(guide)

    def _full_mask(self, guide: _Guide, snap: _Snapshot) -> np.ndarray:
        """The full-resolution mask of ``snap``, computed over the whole ROI."""
        mask = np.zeros(self.shape, bool)
        part, (oy, ox) = _upsample_mask(guide, self._image, snap.low)
        mask[oy : oy + part.shape[0], ox : ox + part.shape[1]] = part
        _clip_to_box(mask, snap.box)
        self._apply_strokes(mask, snap.strokes)
        return mask

    def _refresh_changed(self, guide: _Guide, snap: _Snapshot, prior: np.ndarray, fg: bool) -> np.ndarray:
        """The current mask after a stroke in the same ROI, before its hard constraints.

        Only the part of the ROI whose low-resolution label changed from
        ``prior`` (plus the filter's reach) is brought back to full resolution
        again; the rest is kept. Like the label, the mask moves only the
        stroke's way: a foreground stroke only adds pixels (inside the box),
        a background stroke only removes them.
        """
        mask = self._mask.copy()
        changed = np.nonzero(snap.low != prior)
        if not len(changed[0]):
            return mask
        geom = guide.geom
        d = 2 * _GF_RADIUS + _BAND + 2
        window = (max(0, int(changed[0].min()) - d), min(geom.low_h, int(changed[0].max()) + d + 1),
                  max(0, int(changed[1].min()) - d), min(geom.low_w, int(changed[1].max()) + d + 1))
        part, (oy, ox) = _upsample_mask(guide, self._image, snap.low, window)
        view = mask[oy : oy + part.shape[0], ox : ox + part.shape[1]]
        if fg:
            x0, y0, x1, y1 = snap.box
            view[max(0, y0 - oy) : max(0, y1 - oy), max(0, x0 - ox) : max(0, x1 - ox)] |= (
                part[max(0, y0 - oy) : max(0, y1 - oy), max(0, x0 - ox) : max(0, x1 - ox)])
        else:
            view &= part
        return mask

    def _apply_strokes(self, mask: np.ndarray, strokes: tuple[_Stroke, ...]) -> None:
        """Make every stroke's pixels its label, in order (later ones win)."""
        for s in strokes:
            if s not in self._footprints:
                self._footprints[s] = _polyline_distance_mask(mask.shape, s.points, s.radius)
            hit = self._footprints[s]
            if hit is not None:
                crop, (y0, x0) = hit
                view = mask[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]]
                view[crop] = s.fg

    def _commit(self, guide: _Guide, snap: _Snapshot, mask: np.ndarray) -> None:
        """Make ``snap`` current (the old current goes on the undo stack)."""
        x0, y0, x1, y1 = snap.box
        self._history.append(self._now)
        del self._history[: max(0, len(self._history) - self._max_undo)]
        self._now = dataclasses.replace(snap, mask_bits=np.packbits(mask[y0:y1, x0:x1], axis=None))
        self._mask = mask
        self._guide = guide

    def _restore(self, snap: _Snapshot) -> None:
        """Make ``snap`` current without touching the undo stack."""
        self._now = snap
        self._mask = np.zeros(self.shape, bool)
        if snap.box is not None:
            x0, y0, x1, y1 = snap.box
            self._mask[y0:y1, x0:x1] = _unpack(snap)
            self._guide = self._guide_for(snap.box)
