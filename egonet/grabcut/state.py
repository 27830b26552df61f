"""Undo levels and the session's serialisable state.

A ``_Snapshot`` is everything that defines a session at one undo level: the
box, the strokes, the colour models, the low-resolution cut and the mask
inside the box (packed bits). ``GrabCutSession.state()`` writes the undo
levels as a dict of numpy arrays and scalars (``_encode_state``), which
``GrabCutSession.from_state`` reads back (``_decode_levels``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from egonet import rle
from egonet.errors import EgonetError
from egonet.grabcut.colour import _COMPONENTS, _MODEL_SIZE
from egonet.grabcut.depth import _DEPTH_MODEL_SIZE
from egonet.grabcut.strokes import _Stroke

#: The ``format`` entry of ``GrabCutSession.state()``.
STATE_FORMAT = "egonet.grabcut/1"


@dataclasses.dataclass(frozen=True, eq=False)
class _Snapshot:
    """Everything that defines the session at one undo level."""

    box: tuple[int, int, int, int] | None = None
    strokes: tuple[_Stroke, ...] = ()
    models: np.ndarray | None = None  # (2, 65) float64: background, foreground; (2, 105) with depth
    low: np.ndarray | None = None  # (low_h, low_w) bool, the low-resolution cut
    mask_bits: np.ndarray | None = None  # packed bits of the mask inside the box (outside is False)


def _unpack(snap: _Snapshot) -> np.ndarray:
    """The bool mask inside ``snap``'s box."""
    x0, y0, x1, y1 = snap.box
    size = (y1 - y0) * (x1 - x0)
    return np.unpackbits(snap.mask_bits, count=size).view(bool).reshape(y1 - y0, x1 - x0)


def _encode_state(levels: Sequence[_Snapshot], *, height: int, width: int, work_size: int,
                  max_undo: int, uses_depth: bool = False) -> dict[str, np.ndarray | int | float | str]:
    """The ``state()`` dict of a session's undo levels (oldest first, the current one last).

    Without depth the dict is exactly the colour-only format; with depth the
    models are ``(n, 2, 105)`` and ``uses_depth`` = 1 is added.
    """
    n = len(levels)
    boxes = np.full((n, 4), -1, np.int64)
    models = np.zeros((n, 2, _DEPTH_MODEL_SIZE if uses_depth else _MODEL_SIZE), np.float64)
    low_shape = np.zeros((n, 2), np.int64)
    low_bits: list[np.ndarray] = []
    runs: list[np.ndarray] = []
    index: dict[_Stroke, int] = {}  # strokes shared between levels are stored once
    level_strokes: list[int] = []
    level_offsets = [0]
    for i, snap in enumerate(levels):
        if snap.box is not None:
            boxes[i] = snap.box
            models[i] = snap.models
            low_shape[i] = snap.low.shape
            low_bits.append(np.packbits(snap.low, axis=None))
            runs.append(rle.runs(_unpack(snap)))
        else:
            low_bits.append(np.zeros(0, np.uint8))
            runs.append(np.zeros(0, np.uint32))
        level_strokes.extend(index.setdefault(s, len(index)) for s in snap.strokes)
        level_offsets.append(len(level_strokes))
    table = list(index)
    extra = {"uses_depth": 1} if uses_depth else {}
    return {
        "format": STATE_FORMAT,
        "height": height,
        "width": width,
        "work_size": work_size,
        "max_undo": max_undo,
        "box": boxes,
        "models": models,
        "low_shape": low_shape,
        "low_bits": np.concatenate(low_bits),
        "low_offsets": _offsets(low_bits),
        "mask_rle": np.concatenate(runs),
        "mask_offsets": _offsets(runs),
        "stroke_points": np.concatenate([s.points for s in table]) if table else np.zeros((0, 2)),
        "stroke_point_offsets": _offsets([s.points for s in table]),
        "stroke_fg": np.asarray([s.fg for s in table], np.bool_),
        "stroke_radius": np.asarray([s.radius for s in table], np.float64),
        "level_strokes": np.asarray(level_strokes, np.int64),
        "level_stroke_offsets": np.asarray(level_offsets, np.int64),
        **extra,
    }


def _decode_levels(state: Mapping[str, object], height: int, width: int, *,
                   uses_depth: bool = False) -> list[_Snapshot]:
    """The undo levels of a ``state()`` dict made on a ``width`` x ``height`` frame.

    Raises:
        EgonetError: (field ``state``) if the arrays disagree or a box lies
            outside the frame; numpy's own errors if they are malformed.
    """
    h, w = height, width
    a = {k: np.asarray(state[k]) for k in (
        "box", "models", "low_shape", "low_bits", "low_offsets", "mask_rle", "mask_offsets",
        "stroke_points", "stroke_point_offsets", "stroke_fg", "stroke_radius",
        "level_strokes", "level_stroke_offsets")}
    n = len(a["box"])
    model_size = _DEPTH_MODEL_SIZE if uses_depth else _MODEL_SIZE
    if n < 1 or a["models"].shape != (n, 2, model_size) or a["low_shape"].shape != (n, 2):
        raise EgonetError("state: its arrays disagree on the number of undo levels", field="state")
    weights = a["models"][..., :_COMPONENTS]
    boxed = a["box"][:, 0] >= 0
    if not np.isfinite(a["models"]).all() or (weights < 0).any() or not (weights[boxed].sum(axis=-1) > 0).all():
        raise EgonetError("state: its models are not mixtures (weights must be >= 0, some > 0, all finite)",
                          field="state")
    points, p_off = a["stroke_points"].astype(np.float64), a["stroke_point_offsets"]
    strokes = [_Stroke(points[p_off[i] : p_off[i + 1]].copy(), bool(a["stroke_fg"][i]),
                       float(a["stroke_radius"][i])) for i in range(len(p_off) - 1)]
    levels = []
    for i in range(n):
        ids = a["level_strokes"][a["level_stroke_offsets"][i] : a["level_stroke_offsets"][i + 1]]
        snap_strokes = tuple(strokes[j] for j in ids)
        if a["box"][i][0] < 0:
            levels.append(_Snapshot(strokes=snap_strokes))
            continue
        box = tuple(int(v) for v in a["box"][i])
        if not (0 <= box[0] < box[2] <= w and 0 <= box[1] < box[3] <= h):
            raise EgonetError(f"state: box {box} lies outside the {w}x{h} frame", field="state")
        lh, lw = (int(v) for v in a["low_shape"][i])
        bits = a["low_bits"][a["low_offsets"][i] : a["low_offsets"][i + 1]].astype(np.uint8)
        low = np.unpackbits(bits, count=lh * lw).astype(bool).reshape(lh, lw)
        inside = rle.from_runs(a["mask_rle"][a["mask_offsets"][i] : a["mask_offsets"][i + 1]],
                               (box[3] - box[1], box[2] - box[0]), field="state")
        levels.append(_Snapshot(box=box, strokes=snap_strokes, models=a["models"][i].astype(np.float64),
                                low=low, mask_bits=np.packbits(inside, axis=None)))
    return levels


def _offsets(parts: Sequence[np.ndarray]) -> np.ndarray:
    return np.cumsum([0] + [len(p) for p in parts]).astype(np.int64)

