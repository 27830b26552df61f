"""The learned baselines, fitted per leave-one-activity-out fold and cached.

Each learned baseline (``egonet.baselines``, a ``TrainedBaseline``) is
fitted once per fold: the fold of activity A on the labelled frames of
every *other* activity, so that a frame of A is only ever scored by a model
that never saw A's masks (the paper: "All methods except GBVS were trained
on our dataset using a leave-one-out cross validation"). A table of models
trained on some activities (``Truth.trained_on``; the paper's Tables 3 and
4) has one fold instead: every baseline fitted once on those activities'
frames, as the models were, and scored on the others.

A fitted fold is an ``.npz`` (``egonet.baselines.save_baseline``: settings
and plain arrays, no pickle) under ``CACHE_ROOT/baselines/``, named by the
baseline's key, class version and settings, the held-out activity and a
fingerprint of the training frames (their media, their annotations' ids,
versions, masks and update times, their instances). Editing one frame's
ground truth refits the folds that train on it, never the fold that scores
it. Files are safe to delete (they are fitted again).

A scoring request never fits for long: when the learned baselines' maps
are not cached and fitting and predicting them would take more than
``BASELINE_INLINE_S`` seconds (the classes' planning figures, measured by
``bench/bench_baselines.py``), the request queues ``score_baselines`` for
the worker (``app.tasks``), leaves those rows out with a note, and the next
request after the worker is done reads them from the caches. The CLI
(``flask egonet score``) fits in place, with its progress bar.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from flask import current_app

from app.models import Annotation, Frame
from app.queue import enqueue
from app.services import ground_truth, media
from egonet import io
from egonet.baselines import BASELINES, TrainedBaseline, TrainingFrame, build_baseline, fit_folds, is_trained, load_baseline, params, save_baseline
from egonet.errors import EgonetError

QUEUED_FOR_S = 3600.0
"""A queued job not done after this long is queued again (a worker that died)."""


def trained_keys() -> list[str]:
    """The learned baselines' keys, in the registry's order."""
    return [key for key in BASELINES if is_trained(key)]


def training_frame(frame: Frame, annotation: Annotation) -> TrainingFrame:
    """One labelled frame as a baseline trains on it: colour, DHG (or None), ground truth and labelled instances."""
    rgb = io.read_image(media.local_path(frame.rgb_path))
    dhg = io.read_dhg(media.local_path(frame.dhg_path)) if frame.dhg_path else None
    instances = tuple((inst.label or "", io.read_mask(media.local_path(inst.mask_path))) for inst in annotation.instances)
    return TrainingFrame(rgb, dhg, ground_truth.mask_of(annotation), instances)


def _root() -> Path:
    return Path(current_app.config["CACHE_ROOT"]) / "baselines"


def fold_key(key: str, truth: Any, held_out: str) -> dict[str, Any]:
    """Everything fold ``held_out`` of baseline ``key`` depends on (in a table trained on some activities, one fold: theirs)."""
    cls = BASELINES[key]
    training = [f.id for f in truth.training_frames(held_out)]
    fold = {"trained_on": list(truth.trained_on)} if truth.trained_on else {"held_out": held_out}
    return {"baseline": key, "class": cls.__name__, "version": cls.version, "params": params(build_baseline(key)),
            **fold, "training": truth.digest(training), "frames": len(training)}  # fmt: skip


def fold_path(key: str, truth: Any, held_out: str) -> Path:
    digest = hashlib.sha256(json.dumps(fold_key(key, truth, held_out), sort_keys=True).encode()).hexdigest()
    return _root() / f"{key}-{digest}.npz"


def cached_folds(key: str, truth: Any) -> tuple[dict[str, TrainedBaseline | None], list[str]]:
    """The folds of ``key`` already fitted (None: no other activity to train on), and the activities still to fit."""
    folds: dict[str, TrainedBaseline | None] = {}
    missing = []
    activities = truth.by_activity()
    for activity in activities:
        if not truth.training_frames(activity):  # nothing to fit on
            folds[activity] = None
            continue
        try:
            folds[activity] = load_baseline(BASELINES[key], fold_path(key, truth, activity).read_bytes())
        except (OSError, EgonetError):  # not fitted yet, or a file of another version: fit it
            missing.append(activity)
    return folds, missing


def fit_missing(key: str, truth: Any, on_frame: Callable[[], None] | None = None) -> dict[str, TrainedBaseline | None]:
    """Every fold of ``key``, fitting (and caching) those not cached yet; each frame is read and summarized once."""
    folds, missing = cached_folds(key, truth)
    if not missing:
        return folds

    def frames_of(frames: list[Frame]) -> Iterator[TrainingFrame]:
        for frame in frames:  # read lazily: one frame in memory at a time
            yield training_frame(frame, truth.annotations[frame.id])

    if truth.trained_on:  # one model for every scored activity, fitted on the training activities
        model = build_baseline(key).fit(_counted(frames_of(truth.training_frames(missing[0])), on_frame))
        fitted = dict.fromkeys(missing, model)
        media.write_atomic(fold_path(key, truth, missing[0]), lambda file: save_baseline(model, file))
        return folds | fitted
    fitted = fit_folds(lambda: build_baseline(key), {a: frames_of(f) for a, f in truth.by_activity().items()},
                       folds=missing, on_frame=on_frame)  # fmt: skip
    for activity, model in fitted.items():
        if model is not None:
            media.write_atomic(fold_path(key, truth, activity), lambda file, model=model: save_baseline(model, file))
    return folds | fitted


def _counted(frames: Iterator[TrainingFrame], on_frame: Callable[[], None] | None) -> Iterator[TrainingFrame]:
    for frame in frames:
        yield frame
        if on_frame is not None:
            on_frame()


def seconds_needed(key: str, truth: Any) -> float:
    """A planning estimate of fitting ``key``'s missing folds and predicting every labelled frame."""
    cls: type[TrainedBaseline] = BASELINES[key]
    _, missing = cached_folds(key, truth)
    n = len(truth.frames)
    return (cls.fit_seconds_per_frame * n if missing else 0.0) + cls.predict_seconds_per_frame * n


def _marker(truth: Any, thresholds: int) -> Path:
    return _root() / f"queued-{truth.fingerprint[:16]}-{thresholds}.json"


def defer_to_worker(key: str, truth: Any, thresholds: int) -> str | None:
    """Queue the learned baselines' scoring for the worker when ``key`` would take long now; the note that says so, or None.

    Every learned baseline left out gives the same note (the report says it once).

    The job is queued once per ground truth and number of thresholds (again
    after :data:`QUEUED_FOR_S`); a job that failed says why instead.
    """
    if seconds_needed(key, truth) <= current_app.config["BASELINE_INLINE_S"]:
        return None
    marker = _marker(truth, thresholds)
    try:
        state = json.loads(marker.read_text())
    except (OSError, ValueError):
        state = None
    if state and state.get("error"):
        return f"The worker could not fit the learned baselines not shown: {state['error']}."
    if state is None or time.time() - state.get("queued", 0) > QUEUED_FOR_S:
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(json.dumps({"queued": time.time()}))
        enqueue("score_baselines", thresholds, list(truth.trained_on), truth.columns)
    return ("The learned baselines not shown are being fitted per fold and scored by the worker (`flask egonet worker`); "
            "reload when it is done, or run `flask egonet score` to do it now.")  # fmt: skip


def worker_done(truth: Any, thresholds: int, error: str | None) -> None:
    """The worker finished the queued scoring: forget the marker, or keep the error for the page."""
    marker = _marker(truth, thresholds)
    if error is None:
        marker.unlink(missing_ok=True)
    else:
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(json.dumps({"queued": time.time(), "error": error[:300]}))
