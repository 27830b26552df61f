"""Server-side GrabCut sessions that help draw an annotation's instances.

One ``egonet.grabcut.GrabCutSession`` per user, frame and instance key.
After every operation its state goes into the ``grabcut_state`` row, so the
session survives a restart and any worker process can continue it. Two
strokes never interleave: an operation holds a lock file for its session
(threads and processes of one machine wait for each other), on PostgreSQL
it also locks the row, and the row's revision token catches any writer the
locks cannot see (the operation is then redone on the winner's state). A
worker keeps recent sessions in memory under their revision, within a budget
of bytes, which spares decoding the frame and the state when the same worker
sees the next operation. What one operation may cost is bounded: frames up to
MAX_FRAME_SIDE pixels a side, strokes of up to GRABCUT_MAX_STROKE_POINTS
points and GRABCUT_MAX_RADIUS, and the pixels all of an object's strokes
sweep (a restored session paints them again) up to GRABCUT_MAX_STROKE_PIXELS.

Depth: a box on a frame with stored depth (imported or the demo's) starts a
session that cuts with it, unless the request says ``use_depth: false``. The
session keeps the choice it was made with (its state records it, and a
restored session is given the frame's depth again), so strokes and undo
follow the box; a different choice takes effect from the next box.

A GrabCut step on a model's proposal is an edit: it clears the instance's
proposal mark (``suggest``).
"""

import contextlib
import fcntl
import hashlib
import io
import os
import threading
import zlib
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from flask import current_app
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm.exc import StaleDataError

from app.errors import Problem
from app.extensions import db
from app.models import Annotation, Frame, Instance, Status, User
from app.models.annotations import GrabCutState
from app.services import frames as frames_service
from app.services import media
from egonet import io as egonet_io
from egonet.errors import EgonetError
from egonet.grabcut import GrabCutFrame, GrabCutSession


@dataclass
class GrabCutResult:
    mask: np.ndarray
    can_undo: bool


# --------------------------------------------------------------------------
# What this worker keeps in memory


class _Recent:
    """Recently used objects of this worker, by key, within a budget of bytes:
    the least recently used go first, and one larger than the budget is not kept."""

    def __init__(self):
        self._items: OrderedDict = OrderedDict()  # key -> (value, bytes), least recent first
        self._lock = threading.Lock()
        self.nbytes = 0

    def keys(self) -> list:
        with self._lock:
            return list(self._items)

    def get(self, key):
        with self._lock:
            if key not in self._items:
                return None
            self._items.move_to_end(key)
            return self._items[key][0]

    def take(self, key):
        with self._lock:
            value, size = self._items.pop(key, (None, 0))
            self.nbytes -= size
            return value

    def put(self, key, value, *, nbytes: int, budget: int) -> None:
        with self._lock:
            self.nbytes -= self._items.pop(key, (None, 0))[1]
            if nbytes > budget:
                return
            self._items[key] = (value, nbytes)
            self.nbytes += nbytes
            while self.nbytes > budget:
                _, (_, size) = self._items.popitem(last=False)
                self.nbytes -= size


# Sessions under their row's revision. A session is taken out while an
# operation runs on it (so two threads never share one) and put back under
# the new revision afterwards; since a revision is random and changes with
# every write, a cached session is used only while the database still holds
# exactly its state. A client's keep-alive connection stays with one worker,
# so an annotator's strokes usually find their session here. They are kept
# within GRABCUT_CACHE_BYTES, counted by their own arrays (the mask, the undo
# levels, the stroke footprints: 1-3 MB at 1280x960; the frame and its guides
# are ``_frames``').
_sessions = _Recent()
# Frames ready for GrabCut (``GrabCutFrame``: the decoded image, with or
# without the depth, and the guides of the ROIs cut lately) by their
# (content-addressed, so never stale) media paths, within
# GRABCUT_IMAGE_CACHE_BYTES: a session restored in this worker then only needs
# its state decoded, not the frame, nor its ROI's guides (5-25 ms), again.
# ``_decoded`` and ``_SharedGuides`` share the decoded frames and their
# guides on disk between workers.
_frames = _Recent()


def _dump_state(session: GrabCutSession) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **session.state())
    # np.savez_compressed is several times slower than zlib's fastest level
    # for about the same size on these mostly-bit-packed arrays.
    return zlib.compress(buffer.getvalue(), 1)


def _frame_key(frame: Frame, *, use_depth: bool) -> tuple[str, str | None]:
    return frame.rgb_path, frame.depth_path if use_depth else None


def _grabcut_frame(frame: Frame, *, use_depth: bool) -> GrabCutFrame:
    """The frame for GrabCut, with its depth when ``use_depth`` (it has one): kept by this worker."""
    key = _frame_key(frame, use_depth=use_depth)
    kept = _frames.get(key)
    if kept is None:
        image = _decoded(frame.rgb_path, lambda: egonet_io.read_image(media.local_path(frame.rgb_path)))
        depth = None
        if key[1]:
            depth = _decoded(frame.depth_path, lambda: _missing_as_nan(frames_service.frame_depth(frame)))
        try:
            kept = GrabCutFrame(image, depth, store=_SharedGuides(key))
        except EgonetError as exc:
            raise Problem.from_egonet(exc) from None
    _keep_frame(key, kept)
    return kept


def _keep_frame(key: tuple[str, str | None], kept: GrabCutFrame) -> None:
    """Within GRABCUT_IMAGE_CACHE_BYTES, counted as it is now (again after an operation added guides)."""
    _frames.put(key, kept, nbytes=kept.nbytes, budget=current_app.config["GRABCUT_IMAGE_CACHE_BYTES"])


def _share_frame(key: tuple[str, str | None]) -> None:
    """After an operation: the guides it made go to the other workers, and the frame is counted anew."""
    kept = _frames.get(key)
    if kept is not None:
        kept.share()
        _keep_frame(key, kept)


class _SharedGuides:
    """A frame's GrabCut guides (``GuideStore``) beside the decoded frames on disk.

    A worker that has not seen the frame's ROI yet (a restored session's
    stroke handed to another worker) maps them read-only into memory (well
    under a millisecond; the workers share the pages) instead of building
    them (15-25 ms for a 1408x1408 frame's ROI with depth). One ``.npy`` per
    array under CACHE_ROOT/grabcut-frames, within the same
    GRABCUT_DISK_CACHE_BYTES as the decoded frames; the names hold the
    frame's media paths (content-addressed) and the guide's format and ROI,
    so a copy is never stale. A guide missing an array (trimmed away) or
    that cannot be read or written is built again: the store only saves time.
    """

    def __init__(self, key: tuple[str, str | None]):
        self._folder = Path(current_app.config["CACHE_ROOT"]) / "grabcut-frames"
        self._budget = current_app.config["GRABCUT_DISK_CACHE_BYTES"]
        self._prefix = hashlib.sha256(repr(key).encode()).hexdigest()[:32]

    def load(self, name: str) -> dict[str, np.ndarray] | None:
        stem = f"{self._prefix}-{name}."
        try:
            paths = [entry.path for entry in os.scandir(self._folder)
                     if entry.name.startswith(stem) and entry.name.endswith(".npy")]
            arrays = {Path(p).name[len(stem):-len(".npy")]: np.load(p, mmap_mode="r", allow_pickle=False)
                      for p in paths}
            for p in paths:
                os.utime(p)  # recently used: the last to go
        except (OSError, ValueError):
            return None
        return arrays or None

    def save(self, name: str, arrays: dict[str, np.ndarray]) -> None:
        with contextlib.suppress(OSError):  # a full disk costs the other workers time, not the operation
            for part, array in arrays.items():
                egonet_io.write_atomic(self._folder / f"{self._prefix}-{name}.{part}.npy",
                                       lambda fh, array=array: np.save(fh, np.ascontiguousarray(array)))
            _trim(self._folder, self._budget)


def _decoded(relative: str, decode: Callable[[], np.ndarray]) -> np.ndarray:
    """A frame's image or depth (float32 metres ``(H, W)``, NaN where missing),
    decoded: the copy on disk that the workers share (``.npy`` under
    CACHE_ROOT/grabcut-frames, within GRABCUT_DISK_CACHE_BYTES), mapped
    read-only into memory, else decoded from the media file and shared.
    Mapping a copy costs well under a millisecond and the workers share its
    pages, where decoding a 1408x1408 PNG costs 40-50 ms, so a session
    restored in a worker that has not seen the frame yet stays cheap; and
    GrabCutFrame takes a read-only array without copying it. Media paths are
    content-addressed: a copy is never stale (a copy deleted or replaced while
    mapped stays readable to its mappers)."""
    folder = Path(current_app.config["CACHE_ROOT"]) / "grabcut-frames"
    path = folder / f"{hashlib.sha256(relative.encode()).hexdigest()[:32]}.npy"
    try:
        array = np.load(path, mmap_mode="r", allow_pickle=False)
        os.utime(path)  # recently used: the last to go
        return array
    except (OSError, ValueError):  # none yet (or a foreign file): decode and share
        pass
    array = decode()
    egonet_io.write_atomic(path, lambda fh: np.save(fh, array))
    _trim(folder, current_app.config["GRABCUT_DISK_CACHE_BYTES"])
    return array


def _missing_as_nan(depth: np.ndarray) -> np.ndarray:
    """The stored depth (0 where missing) as GrabCutFrame keeps it (NaN), so it takes the shared copy as it is."""
    return np.where(depth > 0, depth, np.float32(np.nan))


def _trim(folder: Path, budget: int) -> None:
    """Delete the least recently used decoded copies until they fit in ``budget`` bytes."""
    files = []
    for entry in os.scandir(folder):
        with contextlib.suppress(OSError):  # another worker's trim got there first
            stat = entry.stat()
            files.append((stat.st_mtime, stat.st_size, entry.path))
    total = sum(size for _, size, _ in files)
    for _, size, file in sorted(files):
        if total <= budget:
            break
        with contextlib.suppress(OSError):
            os.unlink(file)
        total -= size


def _keep(revision: str, session: GrabCutSession) -> None:
    _sessions.put(revision, session, nbytes=session.nbytes, budget=current_app.config["GRABCUT_CACHE_BYTES"])


def _load_session(frame: Frame, blob: bytes) -> GrabCutSession:
    with np.load(io.BytesIO(zlib.decompress(blob)), allow_pickle=False) as arrays:
        state = dict(arrays)
    # A session made with depth resumes with the frame's depth, one made without without it.
    uses_depth = bool(np.asarray(state.get("uses_depth", 0)).item())
    if uses_depth and frame.depth_path is None:
        raise Problem("box: this object's GrabCut session used the frame's depth, which is gone; draw its box again",
                      status=409, fields={"box": "draw the box again"})
    try:
        return GrabCutSession.from_state(_grabcut_frame(frame, use_depth=uses_depth), state)
    except EgonetError as exc:
        raise Problem.from_egonet(exc) from None


def _new_session(frame: Frame, *, use_depth: bool) -> GrabCutSession:
    return GrabCutSession(_grabcut_frame(frame, use_depth=use_depth and frame.depth_path is not None))


# --------------------------------------------------------------------------
# What one operation may cost


def check_box(frame: Frame, box: list[float]) -> tuple[int, int, int, int]:
    """A box ``[x0, y0, x1, y1]`` (pixels, x1 and y1 exclusive) inside the frame, not empty."""
    x0, y0, x1, y1 = (int(round(v)) for v in box)
    w, h = frame.width, frame.height
    if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
        raise Problem(
            f"box: the box [{x0}, {y0}, {x1}, {y1}] is empty or outside the {w}x{h} frame",
            fields={"box": f"must satisfy 0 <= x0 < x1 <= {w} and 0 <= y0 < y1 <= {h}"},
        )
    if (x0, y0, x1, y1) == (0, 0, w, h):
        raise Problem("box: the box covers the whole frame; leave some background around the object",
                      fields={"box": "covers the whole frame"})
    return x0, y0, x1, y1


def check_stroke(frame: Frame, points: list[list[float]], radius: float) -> None:
    """A stroke with at least one point, a radius in (0, GRABCUT_MAX_RADIUS],
    points no further than a frame's size outside it, touching the frame.
    (The request's schema holds the number of points to
    GRABCUT_MAX_STROKE_POINTS; ``grabcut_stroke`` checks what the object's
    strokes cost in all.)"""
    w, h = frame.width, frame.height
    if not points:
        raise Problem("points: a stroke needs at least one point", fields={"points": "must not be empty"})
    limit = current_app.config["GRABCUT_MAX_RADIUS"]
    if not 0 < radius <= limit:
        raise Problem(f"radius: must be a positive number of pixels up to {limit:g}",
                      fields={"radius": f"must be > 0 and <= {limit:g}"})
    for i, (x, y) in enumerate(points):
        if not (-w <= x <= 2 * w and -h <= y <= 2 * h):
            raise Problem(f"points[{i}]: ({x}, {y}) is far outside the {w}x{h} frame",
                          fields={f"points[{i}]": "far outside the frame"})
    xs = [p[0] for p in points]
    ys = [p[1] for p in points]
    if max(xs) < -radius or min(xs) > w - 1 + radius or max(ys) < -radius or min(ys) > h - 1 + radius:
        raise Problem("points: the stroke lies outside the frame", fields={"points": "outside the frame"})


def stroke_pixels(shape: tuple[int, int], points: list | np.ndarray, radius: float) -> int:
    """The pixels that painting a stroke visits: ``egonet.grabcut`` measures
    the distance to each segment over the segment's box widened by the
    radius, into a crop of the whole stroke's box (all clipped to the frame).
    Its time and memory, and those of replaying the stroke when a worker
    restores the session, follow this number."""
    h, w = shape
    p = np.asarray(points, np.float64).reshape(-1, 2)
    starts, ends = (p, p) if len(p) == 1 else (p[:-1], p[1:])
    lows = np.vstack([np.minimum(starts, ends), p.min(axis=0)])
    highs = np.vstack([np.maximum(starts, ends), p.max(axis=0)])
    x0 = np.clip(np.floor(lows[:, 0] - radius), 0, w)
    y0 = np.clip(np.floor(lows[:, 1] - radius), 0, h)
    x1 = np.clip(np.ceil(highs[:, 0] + radius) + 1, 0, w)
    y1 = np.clip(np.ceil(highs[:, 1] + radius) + 1, 0, h)
    return int((np.maximum(x1 - x0, 0) * np.maximum(y1 - y0, 0)).sum())


def _check_frame_size(frame: Frame) -> None:
    side = current_app.config["MAX_FRAME_SIDE"]
    if max(frame.width, frame.height) > side:
        raise Problem(f"frame_id: frame {frame.id} is {frame.width}x{frame.height}, larger than GrabCut's "
                      f"limit of {side} pixels a side; label it by hand or import it smaller",
                      fields={"frame_id": f"larger than {side} pixels a side"})


def _check_sweep(session: GrabCutSession, points: list, radius: float) -> None:
    """Refuse a stroke that would take the object's strokes past GRABCUT_MAX_STROKE_PIXELS (see ``stroke_pixels``)."""
    limit = current_app.config["GRABCUT_MAX_STROKE_PIXELS"]
    new = stroke_pixels(session.shape, points, radius)
    earlier = sum(stroke_pixels(session.shape, p, r) for p, _, r in session.strokes)
    if new > limit:
        reason = (f"the stroke sweeps {new / 1e6:.1f} Mpx (its segments' boxes widened by the radius), more than "
                  f"the limit of {limit / 1e6:.1f} Mpx; draw shorter strokes or use a smaller brush")
        raise Problem(f"points: {reason}", fields={"points": reason})
    if earlier + new > limit:
        reason = (f"the object's strokes would sweep {(earlier + new) / 1e6:.1f} Mpx, more than the limit of "
                  f"{limit / 1e6:.1f} Mpx; undo some of them or start the object again with a box")
        raise Problem(f"points: {reason}", fields={"points": reason})


# --------------------------------------------------------------------------
# Operations


def grabcut_box(frame: Frame, user: User, key: str, box: tuple[int, int, int, int], *,
                use_depth: bool | None = None) -> GrabCutResult:
    """Start (or restart) the object ``key`` from a box; see ``check_box``.

    Args:
        use_depth: Cut with the frame's depth (True; a 400 naming ``use_depth``
            when the frame has none), without it (False), or with it when
            the frame has depth (None). A box always starts a new session, so
            the choice holds for this object's strokes until its next box.
    """
    has_depth = frame.depth_path is not None
    if use_depth and not has_depth:
        raise Problem(f"use_depth: frame {frame.id} has no depth; send use_depth false (or leave it out)",
                      fields={"use_depth": "this frame has no depth"})
    return _operate(frame, user, key, lambda s: s.box(*box), create=True,
                    use_depth=has_depth if use_depth is None else use_depth)


def grabcut_seed(frame: Frame, user: User, key: str, mask: np.ndarray, *, band: float = 0.0,
                 use_depth: bool | None = None) -> GrabCutResult:
    """Start (or restart) the object ``key`` from a mask, as a box would
    (``GrabCutSession.seed_mask``): kept exactly (``band`` 0) or refined
    within ``band`` pixels of its edge; strokes correct it at once.

    Args:
        mask: bool ``(H, W)`` of the frame's size, not empty.
        band: How far GrabCut may move the mask's edge, pixels.
        use_depth: As for ``grabcut_box``.
    """
    has_depth = frame.depth_path is not None
    if use_depth and not has_depth:
        raise Problem(f"use_depth: frame {frame.id} has no depth; send use_depth false (or leave it out)",
                      fields={"use_depth": "this frame has no depth"})
    return _operate(frame, user, key, lambda s: s.seed_mask(mask, band=band), create=True,
                    use_depth=has_depth if use_depth is None else use_depth)


START_BAND = 8
"""Pixels a stroke's session started from a mask may move its edge (``grabcut_stroke``'s ``start``).
With the edge fixed (0) the engine's models see too little background: a
background stroke then emptied a hand-painted mask of a plain object."""


def grabcut_stroke(frame: Frame, user: User, key: str, *, points: list, label: str, radius: float,
                   start: np.ndarray | None = None) -> GrabCutResult:
    """Add a corrective fg/bg stroke to the object ``key``; see ``check_stroke``.
    The object's strokes in all may sweep at most GRABCUT_MAX_STROKE_PIXELS.

    Args:
        start: The object's mask as the page has it (bool ``(H, W)``), for an
            object this user has no GrabCut session of: one painted by hand,
            fixed by a reviewer, or kept after its sessions went (marked done,
            accepted). The session then starts from that mask as GrabCut's
            trimap (``grabcut_seed`` with ``START_BAND``: the mask eroded by
            the band stays in, beyond it dilated by the band stays out, the
            edge between is GrabCut's to place), and the stroke corrects it.
            Ignored while a session exists.
    """
    if start is not None and (not start.any() or start.all()):
        raise Problem("start: the object's mask is empty or covers the whole frame; draw a box around the object first",
                      fields={"start": "empty or the whole frame"})

    def apply(session: GrabCutSession) -> np.ndarray:
        _check_sweep(session, points, radius)
        return session.stroke(points, label, radius)

    return _operate(frame, user, key, apply, create=False, start=start, use_depth=frame.depth_path is not None)


def grabcut_undo(frame: Frame, user: User, key: str) -> GrabCutResult:
    """Step the object's GrabCut session back by one operation (409 when there is none)."""

    def apply(session: GrabCutSession) -> np.ndarray:
        if not session.can_undo:
            raise Problem("undo: nothing to undo", status=409, fields={"undo": "nothing to undo"})
        return session.undo()

    return _operate(frame, user, key, apply, create=False)


def grabcut_mask(frame: Frame, user: User, key: str) -> GrabCutResult:
    """The session's current mask, without changing it."""
    _check_frame_size(frame)
    row = _state_row(frame, user, key, lock=False)
    if row is None:
        raise Problem(f"no GrabCut session for object {key!r} on this frame", status=404,
                      fields={"instance": "no session"})
    session = _sessions.take(row.revision) or _load_session(frame, row.state)
    _keep(row.revision, session)
    return GrabCutResult(session.mask, session.can_undo)


def _operate(frame: Frame, user: User, key: str, apply: Callable[[GrabCutSession], np.ndarray], *, create: bool,
             use_depth: bool = False, start: np.ndarray | None = None) -> GrabCutResult:
    _check_frame_size(frame)
    # The lock file serialises the workers of one machine; the revision check
    # below still catches a writer that it cannot see (another machine).
    with _session_lock(frame, user, key):
        return _operate_locked(frame, user, key, apply, create=create, use_depth=use_depth, start=start)


def _operate_locked(frame: Frame, user: User, key: str, apply: Callable[[GrabCutSession], np.ndarray], *,
                    create: bool, use_depth: bool, start: np.ndarray | None) -> GrabCutResult:
    """``create``: the operation is a box (or a mask), which may start a
    session (with depth when ``use_depth``); otherwise it continues the saved
    one, or one started from the mask ``start`` when there is none."""
    for _ in range(3):
        row = _state_row(frame, user, key, lock=True)
        try:
            if row is None:
                if not create and start is None:
                    raise Problem("box: draw a box around the object first", fields={"box": "no box yet for this object"})
                session = _new_session(frame, use_depth=use_depth)
                if not create:
                    session.seed_mask(start, band=START_BAND)
            else:
                session = _sessions.take(row.revision) or _load_session(frame, row.state)
                if create and session.uses_depth != use_depth:
                    # A box with the other depth choice: a session cannot change
                    # its models' kind, so the object starts afresh (no undo past it).
                    session = _new_session(frame, use_depth=use_depth)
            mask = apply(session)
        except Problem:
            db.session.rollback()  # let go of the row's lock before answering
            raise
        except EgonetError as exc:
            db.session.rollback()
            raise Problem.from_egonet(exc) from None
        if row is None:
            row = GrabCutState(user_id=user.id, frame_id=frame.id, instance_key=key, state=_dump_state(session))
            db.session.add(row)
        else:
            row.state = _dump_state(session)
        # What comes after the commit, read before it: the commit expires the
        # rows, and reading them again would cost three queries (one the state).
        frame_id, user_id, frame_key = frame.id, user.id, _frame_key(frame, use_depth=session.uses_depth)
        try:
            db.session.flush()
            revision = row.revision
            db.session.commit()
        except (StaleDataError, IntegrityError):
            # Another operation on this session committed first: redo ours on its state.
            db.session.rollback()
            continue
        _keep(revision, session)
        _share_frame(frame_key)
        _clear_proposal(frame_id, user_id, key)
        return GrabCutResult(mask, session.can_undo)
    raise Problem("another GrabCut operation on this object is still running; try again", status=409,
                  fields={"instance": "busy"})


def _clear_proposal(frame_id: int, user_id: int, key: str) -> None:
    """The object was edited: it is no longer an untouched proposal.

    Its own transaction, after the session's: holding the session's row and
    then waiting for instance rows (which a save replaces) could deadlock
    with a save that holds those and forgets sessions. The annotation's
    version stays: the mark is the server's, and the page's next save
    carries the new mask anyway.
    """
    own = db.select(Annotation.id).where(Annotation.frame_id == frame_id, Annotation.author_id == user_id)
    # Edited, the proposal is the annotator's own: the frame is being labelled (annotations._next_status).
    # The annotation's row first, as a save takes it, then the instances'.
    db.session.execute(
        db.update(Annotation)
        .where(Annotation.id.in_(own), Annotation.status == Status.TODO,
               Annotation.instances.any(db.and_(Instance.key == key, Instance.proposal_source.is_not(None))))
        .values(status=Status.IN_PROGRESS)
        .execution_options(synchronize_session=False)
    )
    db.session.execute(
        db.update(Instance)
        .where(Instance.annotation_id.in_(own), Instance.key == key,
               Instance.proposal_source.is_not(None))
        .values(Instance.UNMARKED)
        .execution_options(synchronize_session=False)
    )
    db.session.commit()


# --------------------------------------------------------------------------
# Saved sessions: their rows and locks


def grabcut_keys(frame: Frame, user: User) -> list[str]:
    """The instance keys for which the user has a saved GrabCut session on the frame."""
    return list(
        db.session.execute(
            db.select(GrabCutState.instance_key)
            .filter_by(frame_id=frame.id, user_id=user.id)
            .order_by(GrabCutState.instance_key)
        ).scalars()
    )


def forget_sessions(frame: Frame, user: User, *, keep: set[str | None]) -> None:
    """Delete the user's GrabCut sessions on the frame except those of ``keep``
    (in the caller's transaction)."""
    query = db.delete(GrabCutState).where(GrabCutState.frame_id == frame.id, GrabCutState.user_id == user.id)
    kept = [k for k in keep if k]
    if kept:
        query = query.where(GrabCutState.instance_key.not_in(kept))
    db.session.execute(query)


def _state_row(frame: Frame, user: User, key: str, *, lock: bool) -> GrabCutState | None:
    query = db.select(GrabCutState).filter_by(user_id=user.id, frame_id=frame.id, instance_key=key)
    if lock:
        query = query.with_for_update()
    return db.session.execute(query).scalar_one_or_none()


@contextlib.contextmanager
def _session_lock(frame: Frame, user: User, key: str):
    """Hold an exclusive lock for one GrabCut session, across threads and
    processes on this machine (one of 64 lock files under CACHE_ROOT)."""
    folder = Path(current_app.config["CACHE_ROOT"]) / "grabcut-locks"
    folder.mkdir(parents=True, exist_ok=True)
    stripe = zlib.crc32(f"{user.id}/{frame.id}/{key}".encode()) % 64
    with open(folder / f"{stripe:02d}.lock", "a+b") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
