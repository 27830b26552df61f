"""The one protocol of every baseline, and of the learned ones (as scikit-learn's estimators).

Every baseline answers ``predict(rgb, dhg) -> float32 (H, W)`` in [0, 1] at
the frame's own size (:class:`Predictor`), so scoring treats a baseline and
a trained EgoNet alike; each class names itself with ``name`` (the paper's
name of its row) and ``version`` (bump it when its maps change).

A **learned** baseline subclasses :class:`TrainedBaseline`:

* its constructor only stores settings (keyword arguments, kept as
  attributes of the same names: :meth:`~TrainedBaseline.params`);
* ``fit(frames) -> self`` learns from the training activities'
  :class:`TrainingFrame` objects (colour, DHG, action-object mask, labelled
  instances), consumed one at a time, so a caller can load them lazily;
* ``predict(rgb, dhg)`` maps a frame it never trained on;
* what it learned is plain data, ``state() -> {name: ndarray}`` and
  ``load_state(state) -> self``, written by :func:`save_baseline` as an
  ``.npz`` (never a pickle) with its key, version and settings, and read
  back by :func:`load_baseline`.

``fit`` is two steps, so that leave-one-activity-out can share work between
folds: ``summarize(frame)`` turns one training frame into what the method
learns from (sampled pixel features, proposal features and their overlaps,
a shrunk mask: plain arrays, depending on the settings but never on the
fold), and ``fit_summaries(summaries)`` fits on a fold's. :func:`fit_folds`
summarizes every frame once and fits each fold on the *other* activities'
summaries: seven folds cost one pass over the frames plus seven small fits.
A method for which that split means nothing summarizes a frame into
itself.

Example (a whole learned baseline; :mod:`egonet.baselines` registers it with
one line, ``BASELINES["mean-colour"] = MeanColour``):

    >>> import numpy as np
    >>> class MeanColour(TrainedBaseline):
    ...     '''Pixels whose colour is near the action-objects' mean colour.'''
    ...     name, version = "mean colour", 1
    ...     def __init__(self, *, spread: float = 60.0) -> None:
    ...         self.spread = spread
    ...     def summarize(self, frame):
    ...         return {"sum": frame.rgb[frame.mask].sum(0, dtype=float), "n": np.array(frame.mask.sum())}
    ...     def fit_summaries(self, summaries):
    ...         self.colour_ = sum(s["sum"] for s in summaries) / max(1, sum(int(s["n"]) for s in summaries))
    ...         return self
    ...     def predict(self, rgb, dhg=None):
    ...         d = np.linalg.norm(rgb - self.colour_, axis=-1)
    ...         return np.exp(-(d / self.spread) ** 2).astype(np.float32)
    >>> rgb = np.zeros((4, 4, 3), np.uint8); rgb[1:3, 1:3] = 200
    >>> model = MeanColour().fit([TrainingFrame(rgb, None, rgb[..., 0] > 0)])
    >>> float(model.predict(rgb)[1, 1]), round(float(model.predict(rgb)[0, 0]), 3)
    (1.0, 0.0)
"""

from __future__ import annotations

import inspect
import io
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, ClassVar, Protocol, runtime_checkable

import numpy as np

from egonet.errors import EgonetError
from egonet.saliency import check_frame

__all__ = [
    "Predictor",
    "Summary",
    "TrainedBaseline",
    "TrainingFrame",
    "fit_folds",
    "load_baseline",
    "params",
    "save_baseline",
]

Summary = dict[str, np.ndarray]
"""What one training frame contributes to a fit: named plain arrays."""


@runtime_checkable
class Predictor(Protocol):
    """Anything that maps a frame to an action-object probability map."""

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None) -> np.ndarray:
        """Predict the action-object probability of every pixel.

        Args:
            rgb: Colour frame, uint8 (H, W, 3), RGB order.
            dhg: Depth/height/gray frame, uint8 (H, W, 3), or None for
                predictors that do not use it (or frames without depth).

        Returns:
            Probabilities in [0, 1], float32 (H, W).
        """
        ...


@dataclass(frozen=True, eq=False)
class TrainingFrame:
    """One labelled frame of a training activity.

    Attributes:
        rgb: Colour, uint8 (H, W, 3), RGB order.
        dhg: Depth/height/gray, uint8 (H, W, 3), or None (no depth).
        mask: The action-object mask (the ground truth), bool (H, W).
        instances: The annotation's labelled instances as ``(label, mask)``
            pairs, each mask bool (H, W); ``label`` is the free text of the
            labelling page ("" when none), e.g. ``"hand"``.

    Raises:
        EgonetError: A field of the wrong type or shape (named).
    """

    rgb: np.ndarray
    dhg: np.ndarray | None
    mask: np.ndarray
    instances: tuple[tuple[str, np.ndarray], ...] = ()

    def __post_init__(self) -> None:
        h, w = check_frame(self.rgb, self.dhg)
        for name, m in [("mask", self.mask)] + [(f"instances[{i}]", m) for i, (_, m) in enumerate(self.instances)]:
            if not isinstance(m, np.ndarray) or m.dtype != np.bool_ or m.shape != (h, w):
                raise EgonetError(f"{name} must be a bool ({h}, {w}) mask", field=name.split("[")[0])
        if any(not isinstance(label, str) for label, _ in self.instances):
            raise EgonetError("instances must be (label, mask) pairs with str labels", field="instances")

    def masks_labelled(self, label: str) -> list[np.ndarray]:
        """The masks of the instances labelled ``label`` (compared without case or surrounding spaces)."""
        want = label.strip().lower()
        return [m for name, m in self.instances if name.strip().lower() == want]


class TrainedBaseline:
    """A baseline that learns from labelled frames; see the module docstring.

    Subclasses set ``name`` (the paper's name of the row), ``version``
    (part of every cache key: bump it when fitting or predicting changes)
    and may set ``fit_seconds_per_frame`` and ``predict_seconds_per_frame``
    (planning figures: the scoring service sends long work to the worker),
    and implement
    ``__init__`` (keyword settings stored as same-named attributes),
    :meth:`summarize`, :meth:`fit_summaries` and :meth:`predict`. What
    :meth:`fit_summaries` learns lives in attributes ending in ``_``
    (scikit-learn's convention), plain numpy arrays: :meth:`state` and
    :meth:`load_state` read and write exactly those.
    """

    name: ClassVar[str] = ""
    version: ClassVar[int] = 1
    fit_seconds_per_frame: ClassVar[float] = 0.1
    predict_seconds_per_frame: ClassVar[float] = 0.05

    def params(self) -> dict[str, Any]:
        """The constructor's settings, JSON-ready (tuples become lists): what a cache key needs."""
        return params(self)

    def summarize(self, frame: TrainingFrame) -> Summary:
        """What one training frame contributes to a fit (settings-dependent, never fold-dependent)."""
        raise NotImplementedError

    def fit_summaries(self, summaries: Sequence[Summary]) -> TrainedBaseline:
        """Fit on the training frames' summaries; returns self."""
        raise NotImplementedError

    def fit(self, frames: Iterable[TrainingFrame]) -> TrainedBaseline:
        """Fit on the training activities' frames (consumed one at a time); returns self.

        Raises:
            EgonetError: No frames, or a method's own objection (named).
        """
        summaries = [self.summarize(frame) for frame in frames]
        if not summaries:
            raise EgonetError(f"{self.name or type(self).__name__}: fit needs at least one training frame", field="frames")
        return self.fit_summaries(summaries)

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """The action-object probability of every pixel, float32 (H, W) in [0, 1]."""
        raise NotImplementedError

    @property
    def fitted(self) -> bool:
        return bool(self._state_names())

    def _state_names(self) -> list[str]:
        return sorted(k for k in vars(self) if k.endswith("_") and not k.startswith("_"))

    def check_fitted(self) -> None:
        """Raise a clear error when :meth:`predict` is called before :meth:`fit` or :meth:`load_state`."""
        if not self.fitted:
            raise EgonetError(f"{self.name or type(self).__name__} is not fitted: call fit(frames) or load_state(state) first")

    def state(self) -> dict[str, np.ndarray]:
        """What was fitted, as named plain arrays (the attributes ending in ``_``)."""
        self.check_fitted()
        return {k: np.asarray(getattr(self, k)) for k in self._state_names()}

    def load_state(self, state: Mapping[str, np.ndarray]) -> TrainedBaseline:
        """Restore what :meth:`state` returned; returns self."""
        for key, value in state.items():
            if not key.endswith("_") or key.startswith("_"):
                raise EgonetError(f"{key!r} is not a fitted attribute (they end in '_')", field="state")
            value = np.asarray(value)
            setattr(self, key, value)
        return self


def params(baseline: object) -> dict[str, Any]:
    """Any baseline's constructor settings (stored as same-named attributes), JSON-ready: tuples become lists."""
    names = [p for p in inspect.signature(type(baseline).__init__).parameters if p not in ("self", "args", "kwargs")]
    return json.loads(json.dumps({n: getattr(baseline, n) for n in names}))


def save_baseline(baseline: TrainedBaseline, file: str | Path | BinaryIO) -> None:
    """Write a fitted baseline (its class, version, settings and state) as an ``.npz``; no pickle.

    Args:
        baseline: A fitted baseline.
        file: A path or a binary file object.
    """
    meta = {"class": type(baseline).__name__, "name": baseline.name, "version": baseline.version, "params": baseline.params()}
    arrays = {f"state.{k}": v for k, v in baseline.state().items()}
    np.savez_compressed(file, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)


def load_baseline(cls: type[TrainedBaseline], file: str | Path | BinaryIO | bytes) -> TrainedBaseline:
    """Read what :func:`save_baseline` wrote, as a ``cls`` with the saved settings.

    Raises:
        EgonetError: The file holds another class, another version of it
            (fit again), or is not such a file.
    """
    if isinstance(file, bytes):
        file = io.BytesIO(file)
    try:
        with np.load(file, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            state = {k.removeprefix("state."): data[k] for k in data.files if k.startswith("state.")}
    except (OSError, ValueError, KeyError, EOFError) as exc:
        raise EgonetError(f"not a saved baseline: {exc}", field="file") from None
    if meta.get("class") != cls.__name__ or meta.get("version") != cls.version:
        raise EgonetError(
            f"the file holds {meta.get('class')} version {meta.get('version')}, not {cls.__name__} version {cls.version}: fit it again",
            field="file",
        )
    return cls(**meta["params"]).load_state(state)


def fit_folds(
    make: Callable[[], TrainedBaseline],
    frames_by_activity: Mapping[str, Iterable[TrainingFrame]],
    *,
    folds: Iterable[str] | None = None,
    on_frame: Callable[[], None] | None = None,
) -> dict[str, TrainedBaseline | None]:
    """Leave-one-activity-out: for each activity, a baseline fitted on every *other* activity's frames.

    Every frame is summarized once (by the first baseline ``make`` builds);
    each fold then fits on the other activities' summaries. A baseline
    scored on activity A never saw A's masks.

    Args:
        make: Builds an unfitted baseline (the same settings every call).
        frames_by_activity: Each activity's training frames, consumed once.
        folds: The activities whose fold to fit (default: all).
        on_frame: Called after each frame is summarized (progress).

    Returns:
        The fitted baseline by held-out activity; None where no other
        activity has frames.

    Example:
        >>> import numpy as np
        >>> from egonet.baselines import ActionObjectPrior
        >>> rgb = np.zeros((2, 2, 3), np.uint8)
        >>> frames = {"a": [TrainingFrame(rgb, None, np.eye(2, dtype=bool))], "b": [TrainingFrame(rgb, None, np.ones((2, 2), bool))]}
        >>> fit_folds(lambda: ActionObjectPrior(size=(2, 2)), frames)["a"].prior_
        array([[1., 1.],
               [1., 1.]], dtype=float32)
    """
    summarizer = make()
    summaries: dict[str, list[Summary]] = {}
    for activity, frames in frames_by_activity.items():
        summaries[activity] = []
        for frame in frames:
            summaries[activity].append(summarizer.summarize(frame))
            if on_frame is not None:
                on_frame()
    out: dict[str, TrainedBaseline | None] = {}
    for held_out in summaries if folds is None else folds:
        training = [s for activity, got in summaries.items() if activity != held_out for s in got]
        out[held_out] = make().fit_summaries(training) if training else None
    return out
