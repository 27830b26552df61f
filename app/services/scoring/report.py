"""Building the score table: which runs, studies and baselines, scored (or read from the cache) into rows.

:func:`build_report` turns the choice into jobs (one per run, one for the
baselines, one per participant), each with a cache key; a job's per-frame
statistics are read back from ``cache`` or scored by ``sources`` and written
there, then ``rows`` reduces them to the rows of a
:class:`~app.services.scoring.table.Report` under the chosen convention,
frames and resamples. :func:`load_sources` is the first half alone (the
per-frame page uses it).

A new kind of row registers in :func:`_jobs`: a function that returns
:class:`_Job` objects (their rows, cache key and how to score them).
"""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import timedelta
from typing import Any, NamedTuple

import numpy as np
from sqlalchemy import func

from app.extensions import db
from app.models.frames import Frame
from app.models.studies import ANSWERED, EndReason, FrameKind, Outcome, Participant, Study, StudyFrame, Trial
from app.models import Activity, Annotation
from app.models.training import FoldsMode, Prediction, TrainingRun
from app.services import attention_points, ground_truth
from app.services import studies as studies_service
from app.services import training
from app.services.scoring import cache, sources
from app.services.scoring.cells import BASELINE, COLUMNS, FRAMES, HUMAN, MODEL
from app.services.scoring.provenance import HumanMaps, Provenance
from app.services.scoring.rows import Scorer, ScoringProblem, Source, build_rows, compare, frames_without_truth, without_frames_without_truth
from app.services.scoring import fitting
from app.services.scoring.sources import Scored, Truth
from app.services.scoring.table import Report
from app.version import code_version
from egonet.baselines import BASELINES, build_baseline, is_trained, params
from egonet.clicks import DEFAULT_SIGMA, METHOD_OPTIONS, SUPERPIXEL_DEFAULTS
from egonet.errors import EgonetError
from egonet.metrics import (
    DEFAULT_EMPTY,
    DEFAULT_RESAMPLES,
    DEFAULT_THRESHOLDS,
    MAX_RESAMPLES,
    PER_FRAME_MEANS,
    Resampler,
    resolve_metric,
    threshold_values,
)
from egonet.metrics.frames import check_empty

__all__ = ["ScoringProblem", "available_runs", "available_studies", "build_report", "load_sources", "table_runs", "training_sets"]

# Training options that do not change what a run learns: runs differing only in these (and the seed) are grouped.
_NOT_THE_EXPERIMENT = ("seed", "device", "num_workers")


# --------------------------------------------------------------------------
# Choosing what to score


def available_runs() -> list[TrainingRun]:
    """Completed training runs, newest first."""
    return training.completed_runs()


def available_studies() -> list[tuple[Study, int]]:
    """Every study with its number of participants, newest first."""
    counts = dict(db.session.execute(db.select(Participant.study_id, func.count()).group_by(Participant.study_id)).all())
    chosen = db.session.execute(db.select(Study).order_by(Study.created_at.desc(), Study.id.desc())).scalars()
    return [(s, counts.get(s.id, 0)) for s in chosen]


def training_sets() -> dict[tuple[str, ...], list[int]]:
    """The activities completed runs on every frame (``folds="all"``) were trained on, each with its runs' ids, newest first."""
    out: dict[tuple[str, ...], list[int]] = {}
    for run in available_runs():
        if run.folds is FoldsMode.ALL:
            out.setdefault(tuple(training.trained_on(run)), []).append(run.id)
    return out


def table_runs(trained_on: Sequence[str] = (), runs: Sequence[TrainingRun] | None = None) -> list[TrainingRun]:
    """The completed runs of the table trained on ``trained_on``: runs on every frame of exactly those activities;
    for () (leave-one-activity-out, Table 2) every other completed run."""
    wanted = tuple(sorted(trained_on))
    return [run for run in (available_runs() if runs is None else runs) if tuple(training.trained_on(run)) == wanted]


def _choose_runs(run_ids: Sequence[int] | None, trained_on: Sequence[str] | None, notes: list[str]) -> tuple[list[TrainingRun], tuple[str, ...]]:
    """The runs of the table and its training set: () for leave-one-activity-out (Table 2), else the activities
    the runs on every frame were trained on (Tables 3 and 4; given, or inferred from the runs chosen).

    One table, one training set: the baselines are fitted on the same activities as its models.
    """
    runs = available_runs()
    if trained_on is not None:
        trained_on = tuple(sorted(dict.fromkeys(trained_on)))
        known = set(db.session.execute(db.select(Activity.name).where(Activity.name.in_(trained_on))).scalars())
        if not trained_on or (unknown := [a for a in trained_on if a not in known]):
            raise ScoringProblem(f"trained_on: no activity named {', '.join(map(repr, unknown)) if trained_on else 'given'}",
                                 field="trained_on")  # fmt: skip
    by_id = {run.id: run for run in runs}
    if run_ids is not None:
        unknown = [i for i in run_ids if i not in by_id]
        if unknown:
            raise ScoringProblem(f"run {unknown[0]} is not a completed training run", field="runs")
        runs = [by_id[i] for i in dict.fromkeys(run_ids)]
        sets = {tuple(training.trained_on(run)) for run in runs}
        if trained_on is None and len(sets) > 1:
            which = "; ".join(f"run {r.id}: {', '.join(training.trained_on(r)) or f'{r.folds} folds'}" for r in runs)
            raise ScoringProblem(f"the runs chosen were trained on different activities ({which}): a table has one "
                                 "training set, choose runs of one", field="runs")  # fmt: skip
        if trained_on is None and runs and runs[0].folds is FoldsMode.ALL:
            trained_on = sets.pop()  # the runs chosen say what the table was trained on
        for run in runs:
            if tuple(training.trained_on(run)) != (trained_on or ()):
                raise ScoringProblem(_other_training_set(run, trained_on or ()), field="runs")
        return runs, trained_on or ()
    chosen = table_runs(trained_on or (), runs)
    if not trained_on:
        left = training_sets()
        notes += [f"Runs {', '.join(map(str, ids))} trained on every frame of {', '.join(names)} are in the table trained on "
                  f"{'them' if len(names) > 1 else 'it'}, not in this one." for names, ids in left.items()]  # fmt: skip
    return chosen, trained_on or ()


def _other_training_set(run: TrainingRun, trained_on: tuple[str, ...]) -> str:
    """Why ``run`` is not a row of a table trained on ``trained_on`` (one table, one training set)."""
    table = f"trained on {', '.join(trained_on)}" if trained_on else "of leave-one-activity-out folds (Table 2)"
    if run.folds is FoldsMode.ALL:
        return (f"run {run.id} was trained on every frame of {', '.join(training.trained_on(run))}: it is not a row of "
                f"the table {table}; choose its training set (trained_on)")  # fmt: skip
    return f"run {run.id} ({run.folds} folds) is not a row of the table {table}: it was not trained on exactly those activities"


def _choose_studies(study_ids: Sequence[int] | None) -> list[int]:
    if study_ids is None:
        return list(db.session.execute(db.select(Study.id).order_by(Study.id)).scalars())
    wanted = list(dict.fromkeys(study_ids))
    known = set(db.session.execute(db.select(Study.id).where(Study.id.in_(wanted))).scalars())
    unknown = [i for i in wanted if i not in known]
    if unknown:
        raise ScoringProblem(f"study {unknown[0]} does not exist", field="studies")
    return wanted


# --------------------------------------------------------------------------
# Jobs: rows scored in one pass, with their cache key


class _RowSpec(NamedTuple):
    key: str
    stats: str  # which of the job's statistics the row shows
    name: str
    kind: str
    detail: str
    signature: str | None = None  # runs with equal signatures differ only in their seed
    label: str = ""
    seed: int | None = None


@dataclass
class _Job:
    """Rows that are scored in one pass, their cache key and how to score them."""

    rows: list[_RowSpec]
    cache_key: dict[str, Any]
    frames: int  # frames it will score, for progress (0 when unknown)
    score: Callable[[Callable[[int], None]], Scored]
    notes: list[str] = field(default_factory=list)  # said whenever the job's rows are shown
    # When the statistics are not cached: queues the job for the worker and returns the note that says so, or None (score now).
    defer: Callable[[], str | None] | None = None


def _run_signature(run: TrainingRun) -> str | None:
    """Everything a run's training depends on but its seed; None for a run without a recorded configuration."""
    if not isinstance(run.config, dict) or "train" not in run.config:
        return None
    train = {k: v for k, v in run.config["train"].items() if k not in _NOT_THE_EXPERIMENT}
    rest = {k: v for k, v in run.config.items() if k not in ("train", "worker_stopped")}
    what = {"model": run.model_name, "options": run.model_options, "folds": str(run.folds), "train": train, **rest}
    return json.dumps(what, sort_keys=True, default=str)


def _run_job(run: TrainingRun, truth: Truth, thresholds: int) -> _Job:
    # ``flask egonet predict`` may replace a run's held-out maps: they are part of the key.
    predictions = db.session.execute(
        db.select(func.count(), func.max(Prediction.id)).where(Prediction.run_id == run.id, Prediction.held_out.is_(True))
    ).one()
    spec = _RowSpec(
        f"run:{run.id}",
        "",
        sources.run_row_name(run),
        MODEL,
        (f"{run.name}, trained on: {', '.join(training.trained_on(run))}, seed {run.seed}" if run.folds is FoldsMode.ALL
         else f"{run.name}, {run.folds} folds, seed {run.seed}"),
        signature=_run_signature(run),
        label=sources.model_label(run),
        seed=run.seed,
    )
    return _Job(
        rows=[spec],
        cache_key={"run": run.id, "predictions": list(predictions), "truth": truth.fingerprint, "thresholds": thresholds},
        # Leave-one-activity-out holds every labelled frame out once.
        frames=len(truth.frames) if run.folds == "loao" else 0,
        score=lambda progress: sources.run_stats(run, truth, thresholds, progress),
    )


def _baseline_jobs(truth: Truth, thresholds: int, *, fit_in_worker: bool) -> list[_Job]:
    """One job per baseline; a learned one's is fitted per leave-one-activity-out fold (``fitting``), in the worker when long.

    In a table trained on some activities, a learned one is fitted once, on those.
    """
    jobs = []
    fitted = (f"trained on: {', '.join(truth.trained_on)}" if truth.trained_on
              else "fitted per fold under leave-one-activity-out")
    for key, cls in BASELINES.items():
        trained = is_trained(key)
        detail = fitted if trained else "not trained"
        jobs.append(
            _Job(
                rows=[_RowSpec(f"baseline:{key}", "", sources.baseline_name(key, truth), BASELINE, detail)],
                cache_key={"baseline": key, "version": cls.version, "params": params(build_baseline(key)),
                           "truth": truth.fingerprint, "thresholds": thresholds},  # fmt: skip
                # A learned baseline reads every frame twice (its folds' fit, then its maps) unless its folds are cached.
                frames=len(truth.frames) * (2 if trained else 1),
                score=lambda progress, key=key: sources.baseline_stats(key, truth, thresholds, progress),
                defer=(lambda key=key: fitting.defer_to_worker(key, truth, thresholds)) if trained and fit_in_worker else None,
            )
        )
    return jobs


def _session_over(person: Participant) -> bool:
    """Whether the participant can answer no more (finished, or past the deadline and its grace)."""
    if person.finished_at is not None:
        return True
    limit = person.deadline + timedelta(seconds=studies_service.LATE_GRACE_S) if person.deadline else None
    return limit is not None and studies_service.now() > limit


def _participant_jobs(
    study_ids: list[int], truth: Truth, thresholds: int, notes: list[str], *, exclude_failed_checks: bool, by_condition: bool
) -> list[_Job]:
    chosen = sources.human_participants(study_ids, exclude_failed_checks=exclude_failed_checks, by_condition=by_condition)
    participants = [person for person, _ in chosen]
    if exclude_failed_checks:
        left_out = len(studies_service.study_participants(study_ids)) - len(participants)
        if left_out:
            notes.append(f"{left_out} participant{'s' if left_out != 1 else ''} who failed a check left out.")
    # Only the timed part's main trials are scored (never practice or catch trials).
    trials: dict[int, list[tuple[int, Outcome | None]]] = defaultdict(list)
    for pid, tid, outcome in db.session.execute(
        db.select(Trial.participant_id, Trial.id, Trial.outcome)
        .join(StudyFrame, StudyFrame.id == Trial.study_frame_id)
        .where(Trial.participant_id.in_([p.id for p in participants]), StudyFrame.kind == FrameKind.MAIN)
        .order_by(Trial.id)
    ):
        trials[pid].append((tid, outcome))
    jobs = []
    for person, condition in chosen:
        name = person.label if len(study_ids) == 1 else f"{person.label} (study {person.study_id})"
        if condition is not None:
            name = f"{name} [{condition or 'no condition'}]"
        if person.end_reason is EndReason.DECLINED or person.started_at is None:
            notes.append(f"{name} {'declined consent' if person.end_reason is EndReason.DECLINED else 'has not started'}.")
            continue
        over = _session_over(person)
        answered = [(t, str(o)) for t, o in trials[person.id] if o in ANSWERED]
        unanswered = [(t, "unanswered") for t, o in trials[person.id] if o is Outcome.EXPIRED or (over and o is None)]
        pending = sum(1 for _, o in trials[person.id] if o is None and not over)
        if not answered and not unanswered:
            notes.append(f"{name} has no answered trials yet.")
            continue
        job_notes = [f"{name} is still in session: trials not answered yet ({pending}) are left out."] if pending else []
        jobs.append(
            _Job(
                rows=[_RowSpec(f"participant:{person.id}", "", name, HUMAN, f"{person.study.name}, participant {person.number}")],
                # Answers are never changed once given: the trials and their outcomes say whether the scores still hold.
                cache_key={"participant": person.id, "trials": sorted(answered + unanswered), "truth": truth.fingerprint, "thresholds": thresholds},
                frames=len(answered) + len(unanswered),
                score=lambda progress, person=person, over=over: sources.participant_stats(
                    person, truth, thresholds, progress, session_over=over
                ),
                notes=job_notes,
            )
        )
    return jobs


def _jobs(
    run_ids: Sequence[int] | None,
    study_ids: Sequence[int] | None,
    baselines: bool,
    thresholds: int,
    notes: list[str],
    *,
    exclude_failed_checks: bool = False,
    by_condition: bool = False,
    fit_in_worker: bool = False,
    trained_on: Sequence[str] | None = None,
    columns: str = "activities",
) -> tuple[list[_Job], Truth]:
    """Every job of the choice, in table order: models, baselines, people; and the ground truth (its ``trained_on``
    the table's training set)."""
    runs, trained_on = _choose_runs(run_ids, trained_on, notes)
    chosen_studies = _choose_studies(study_ids)
    truth = sources.load_truth(trained_on, columns)
    jobs = [_run_job(run, truth, thresholds) for run in runs]
    if baselines and truth.frames:
        jobs += _baseline_jobs(truth, thresholds, fit_in_worker=fit_in_worker)
    return jobs + _participant_jobs(
        chosen_studies, truth, thresholds, notes, exclude_failed_checks=exclude_failed_checks, by_condition=by_condition
    ), truth


# --------------------------------------------------------------------------
# Building the report


def load_sources(
    *,
    run_ids: Sequence[int] | None = None,
    study_ids: Sequence[int] | None = None,
    baselines: bool = True,
    thresholds: int = DEFAULT_THRESHOLDS,
    answered_only: bool = False,
    exclude_failed_checks: bool = False,
    by_condition: bool = False,
    use_cache: bool = True,
    fit_in_worker: bool = False,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
    trained_on: Sequence[str] | None = None,
    columns: str = "activities",
) -> tuple[list[Source], list[str]]:
    """Every chosen row's per-frame statistics, from the cache or scored now (and cached), and the notes.

    Arguments as :func:`build_report`. A job whose maps cannot be scored
    (say, a run whose predictions do not match the frames' sizes) becomes a
    note instead of rows.
    """
    found, notes, _ = _load_sources(
        run_ids=run_ids, study_ids=study_ids, baselines=baselines, thresholds=thresholds, answered_only=answered_only,
        exclude_failed_checks=exclude_failed_checks, by_condition=by_condition, use_cache=use_cache,
        fit_in_worker=fit_in_worker, on_start=on_start, on_progress=on_progress, trained_on=trained_on, columns=columns,
    )
    return found, notes


def _load_sources(
    *,
    run_ids: Sequence[int] | None,
    study_ids: Sequence[int] | None,
    baselines: bool,
    thresholds: int,
    answered_only: bool,
    exclude_failed_checks: bool,
    by_condition: bool,
    use_cache: bool,
    fit_in_worker: bool,
    on_start: Callable[[int], None] | None,
    on_progress: Callable[[int], None] | None,
    trained_on: Sequence[str] | None,
    columns: str = "activities",
) -> tuple[list[Source], list[str], Truth]:
    """:func:`load_sources`, and the ground truth (its ``trained_on`` the table's training set, () for leave-one-activity-out)."""
    try:
        threshold_values(thresholds)
    except ValueError as exc:
        raise ScoringProblem(str(exc), field="thresholds") from None
    if columns not in COLUMNS:
        raise ScoringProblem(f"columns must be one of {', '.join(COLUMNS)}, got {columns!r}", field="columns")
    notes: list[str] = []
    jobs, truth = _jobs(
        run_ids, study_ids, baselines, thresholds, notes, exclude_failed_checks=exclude_failed_checks, by_condition=by_condition,
        fit_in_worker=fit_in_worker, trained_on=trained_on, columns=columns,
    )
    cached = [(cache.cache_path(job.cache_key), job) for job in jobs]
    cached = [(path, job, cache.read_cached(path, thresholds) if use_cache else None) for path, job in cached]
    deferred = {id(job): job.defer() for _, job, got in cached if got is None and job.defer is not None}
    notes += list(dict.fromkeys(note for note in deferred.values() if note))
    cached = [(path, job, got) for path, job, got in cached if not deferred.get(id(job))]
    if on_start is not None:
        on_start(sum(job.frames for _, job, got in cached if got is None))
    out = []
    for path, job, got in cached:
        if got is None:
            try:
                got = job.score(on_progress or (lambda n: None))
            except ValueError as exc:  # a map or mask that egonet.metrics refuses
                notes.append(f"{job.rows[0].name} could not be scored: {exc}")
                continue
            cache.write_cached(path, *got)
        stats, job_notes = got
        notes += job_notes + job.notes
        for spec in job.rows:
            found = stats.get(spec.stats)
            if found is not None and answered_only:
                found = found.take(found.answered)
            if found is None or found.n == 0:
                if not job_notes:  # else the job has said why
                    notes.append(f"{spec.name} has no frames with a ground truth to score.")
                continue
            unanswered = int(np.count_nonzero(~stats[spec.stats].answered)) if spec.kind == HUMAN else None
            out.append(Source(spec.key, spec.name, spec.kind, spec.detail, found, unanswered, spec.signature, spec.label, spec.seed))
    return out, notes, truth


def _check_view(metric: str, frames: str, empty: str, resamples: int, seed: int) -> tuple[str, list[str]]:
    """The convention's name (an old one resolved) and the notes that say so."""
    try:
        metric, deprecated = resolve_metric(metric)
        check_empty(empty)
    except EgonetError as exc:
        raise ScoringProblem(exc.message, field=exc.field) from None
    if frames not in FRAMES:
        raise ScoringProblem(f"frames must be one of {', '.join(FRAMES)}, got {frames!r}", field="frames")
    if isinstance(resamples, bool) or not isinstance(resamples, int) or not 0 <= resamples <= MAX_RESAMPLES:
        raise ScoringProblem(f"resamples must be a whole number from 0 to {MAX_RESAMPLES}", field="resamples")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ScoringProblem("seed must be a whole number >= 0", field="seed")
    return metric, [f"{deprecated}."] if deprecated else []


def build_report(
    *,
    run_ids: Sequence[int] | None = None,
    study_ids: Sequence[int] | None = None,
    baselines: bool = True,
    thresholds: int = DEFAULT_THRESHOLDS,
    metric: str = "pooled",
    frames: str = "shared",
    empty: str = DEFAULT_EMPTY,
    answered_only: bool = False,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    compare_keys: tuple[str, str] | None = None,
    exclude_failed_checks: bool = False,
    by_condition: bool = False,
    use_cache: bool = True,
    fit_in_worker: bool = False,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
    trained_on: Sequence[str] | None = None,
    columns: str = "activities",
) -> Report:
    """Score the chosen runs, the baselines and the chosen studies' participants.

    Args:
        run_ids: Completed training runs to include; None for all of them.
        study_ids: Studies whose participants to include; None for all.
        baselines: Include the baselines (``egonet.baselines.BASELINES``); the learned ones
            are fitted per leave-one-activity-out fold (``fitting``).
        thresholds: The number T of thresholds ``k / (T + 1)``.
        metric: The convention: ``"pooled"``, ``"ois-mean"``,
            ``"mean-curve"`` or ``"ods-ois"`` (``egonet.metrics.frames``;
            ``"per-image"``, the old name of ``"ois-mean"``, adds a note).
        frames: ``"shared"``: score each activity on the frames every row
            there has; ``"each"``: every row on all its frames.
        empty: How the per-frame means count a frame without action-object
            pixels: ``"leave-out"`` (default), ``"zero"`` or ``"one-if-empty"``.
        answered_only: Leave out participants' unanswered trials (by default
            each counts as an empty map).
        resamples: Bootstrap resamples for the 95 % intervals (0: none).
        seed: The bootstrap's seed.
        compare_keys: Two row keys to compare with a paired test (``report.comparison``).
        exclude_failed_checks: Leave out participants who failed a
            comprehension or attention (catch trial) check.
        by_condition: Split the human rows by the studies' conditions
            (ordered and named by condition).
        use_cache: Read statistics cached by an earlier report with the
            same inputs (they are written either way).
        fit_in_worker: Queue learned baselines that would take longer than
            ``BASELINE_INLINE_S`` for the worker and leave their rows out with
            a note (the pages); else fit and score them now (the CLI, the worker).
        on_start: Called once with the number of frames to score.
        on_progress: Called with the number of frames just scored.
        trained_on: The table's training set, for models scored where they
            were never trained (the paper's Tables 3 and 4): its rows are the
            runs on every frame (``folds="all"``) of exactly these activities,
            the learned baselines are fitted once on them, and the columns are
            the other activities. ``None``: leave-one-activity-out (Table 2),
            unless ``run_ids`` are all runs on every frame of one set of activities.
        columns: ``"activities"`` (default) or ``"sequences"``: each
            activity's recordings as columns of their own (a dataset of videos
            imported as one activity, as the paper's Tables 3 and 4 list them).

    Returns:
        The :class:`Report`, its ``provenance`` filled in.

    Raises:
        ScoringProblem: naming ``runs``, ``studies``, ``thresholds``,
            ``metric``, ``frames``, ``empty``, ``resamples``, ``seed`` or ``compare``.

    Example::

        report = build_report(run_ids=[3], study_ids=[1], metric="ois-mean")
        print(report.to_table())
    """
    metric, notes = _check_view(metric, frames, empty, resamples, seed)
    found, loaded, truth = _load_sources(
        run_ids=run_ids, study_ids=study_ids, baselines=baselines, thresholds=thresholds, answered_only=answered_only,
        exclude_failed_checks=exclude_failed_checks, by_condition=by_condition, use_cache=use_cache,
        fit_in_worker=fit_in_worker, on_start=on_start, on_progress=on_progress, trained_on=trained_on, columns=columns,
    )
    truths, frames_scored, column_of = _scored_frames(found)
    provenance = Provenance(
        metric=metric, thresholds=thresholds, frames=frames, empty=empty, empty_frames=frames_without_truth(found),
        answered_only=answered_only, resamples=resamples, seed=seed, code_version=code_version(),
        human_maps=_human_maps(found, exclude_failed_checks=exclude_failed_checks), model_splits=_model_splits(found),
        trained_on=truth.trained_on, training_frames=_training_frames(truth), column_kind=columns,
        ground_truth=attention_points.activity_sources(truths, column_of), predicted_depth=_predicted_depth(frames_scored, column_of),
    )
    return _scored(found, notes + loaded, provenance, compare_keys=compare_keys)


def _scored(found: list[Source], notes: list[str], provenance: Provenance, *, compare_keys: tuple[str, str] | None) -> Report:
    """The loaded sources as the report's rows, under the provenance's convention and frames, with the comparison asked for."""
    if provenance.metric in PER_FRAME_MEANS and provenance.empty == "leave-out":
        found, left = without_frames_without_truth(found)
        notes = notes + left
    scorer = Scorer(provenance.metric, Resampler(resamples=provenance.resamples, seed=provenance.seed), provenance.empty)
    rows, activities, frame_notes = build_rows(found, frames=provenance.frames, scorer=scorer)
    comparison = compare(found, *compare_keys, scorer=scorer, provenance=provenance) if compare_keys else None
    return Report(activities=activities, rows=rows, provenance=provenance, notes=frame_notes + notes, comparison=comparison)


def _scored_frames(found: list[Source]) -> tuple[dict[int, Annotation], dict[int, Frame], dict[int, str]]:
    """The frames the rows are scored on: their ground-truth annotations, the frames, and each frame's column."""
    column_of: dict[int, str] = {}
    for source in found:
        column_of.update(zip(source.stats.ids.tolist(), source.stats.activities.tolist()))
    ids, truths, frames = sorted(column_of), {}, {}
    for start in range(0, len(ids), 5000):  # keep IN lists well under SQLite's variable limit
        chunk = ids[start : start + 5000]
        truths.update(ground_truth.ground_truths(chunk))
        frames.update((f.id, f) for f in db.session.execute(db.select(Frame).where(Frame.id.in_(chunk))).scalars())
    return truths, frames, column_of


def _training_frames(truth: Truth) -> dict[str, int]:
    """The labelled frames of each training activity (what the table's learned baselines were fitted on)."""
    counts = Counter(truth.activity[f.id] for f in truth.frames)
    return {a: counts[a] for a in truth.trained_on}


def _predicted_depth(frames: dict[int, Frame], column_of: dict[int, str]) -> dict[str, int]:
    """Per column, the scored frames whose depth and DHG were predicted (``Frame.depth_predicted``)."""
    return dict(sorted(Counter(column_of[i] for i, frame in frames.items() if frame.depth_predicted).items()))


def _model_splits(found: list[Source]) -> dict[str, str]:
    """How each model row's run was split (``loao``, ``single``, ``released``, ``all``), by row key."""
    runs = {f"run:{i}": str(folds) for i, folds in db.session.execute(
        db.select(TrainingRun.id, TrainingRun.folds).where(TrainingRun.id.in_([int(s.key.split(":", 1)[1]) for s in found if s.kind == MODEL]))
    )}  # fmt: skip
    return {s.key: runs[s.key] for s in found if s.key in runs}


def _human_maps(found: list[Source], *, exclude_failed_checks: bool) -> tuple[HumanMaps, ...]:
    """How each study with a human row ran (frames, draw, practice and catch trials, who was left out) and made its maps."""
    people = dict(db.session.execute(
        db.select(Participant.id, Participant.study_id).where(Participant.id.in_([int(s.key.split(":", 1)[1]) for s in found if s.kind == HUMAN]))
    ).all())  # fmt: skip
    if not people:
        return ()
    chosen = db.session.execute(db.select(Study).where(Study.id.in_(set(people.values()))).order_by(Study.id)).scalars()
    out = []
    for study in chosen:
        everyone = studies_service.study_participants([study.id])
        pilots = db.session.scalar(
            db.select(func.count()).where(Participant.study_id == study.id, Participant.pilot.is_(True), Participant.withdrawn_at.is_(None))
        )
        main = len(study.frames_of(FrameKind.MAIN))
        out.append(HumanMaps(
            study=f'study {study.id} "{study.name}"', regions=_regions(study.superpixels or {}), sigma=_sigma(study),
            rows=tuple(f"participant:{pid}" for pid, sid in people.items() if sid == study.id),
            frames=main, per_activity=study.frames_per_activity, activities=main // max(study.frames_per_activity, 1),
            seed=study.seed, order=str(study.activity_order), practice=len(study.frames_of(FrameKind.PRACTICE)),
            catch=len(study.frames_of(FrameKind.CATCH)), pilots=pilots or 0,
            failed_checks=sum(1 for c in studies_service.checks_of(everyone).values() if c.passed is False),
            excluded=exclude_failed_checks,
        ))  # fmt: skip
    return tuple(out)


REGION_WORDS = {
    "hierarchical": "hierarchical superpixel regions (about {fine_regions} watershed regions merged along colour boundaries weaker than {level})",
    "slic": "SLIC superpixels (about {n_segments} regions, compactness {compactness})",
    "felzenszwalb": "Felzenszwalb-Huttenlocher graph regions (scale {scale}, at least {min_size} pixels each)",
}
"""Each region method and its options, in words (``egonet.clicks.METHOD_OPTIONS``)."""


def _regions(settings: dict[str, Any]) -> str:
    method = settings.get("method", SUPERPIXEL_DEFAULTS.method)
    return REGION_WORDS[method].format(**{k: settings.get(k, getattr(SUPERPIXEL_DEFAULTS, k)) for k in METHOD_OPTIONS[method]})


def _sigma(study: Study) -> str:
    if study.sigma_scaled:
        return (f"a standard deviation of {DEFAULT_SIGMA:g} px at {studies_service.REFERENCE_WIDTH} px wide, scaled to each "
                f"frame's width ({study.sigma_px:g} px on the widest)")  # fmt: skip
    return f"a standard deviation of {study.sigma_px:g} px at the frames' native resolution"
