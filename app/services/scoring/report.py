"""Building the score table: which runs, studies and baselines, scored (or read from the cache) into rows.

:func:`build_report` turns the choice into jobs (one per run, one for the
baselines, one per participant), each with a cache key; a job's statistics
are read back from ``cache`` or scored by ``sources`` and written there,
then reduced to the rows of a :class:`~app.services.scoring.table.Report`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from sqlalchemy import func

from app.errors import Problem
from app.extensions import db
from app.models.studies import ANSWERED, Participant, Study, Trial
from app.models.training import Prediction, TrainingRun
from app.services import training
from app.services import studies as studies_service
from app.services.scoring import cache, sources
from app.services.scoring.cache import Stats
from app.services.scoring.sources import AOP_SIZE, BASELINE_NAMES, CENTER_SIGMA, SALIENCY, Scored, Truth
from app.services.scoring.table import ALL, BASELINE, HUMAN, MODEL, Cell, Curve, Report, Row
from egonet.metrics import DEFAULT_THRESHOLDS, ScoreAccumulator, threshold_values


class ScoringProblem(Problem):
    """A score request that cannot go ahead; ``field`` names the bad input."""


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


def _choose_runs(run_ids: Sequence[int] | None) -> list[TrainingRun]:
    runs = available_runs()
    if run_ids is None:
        return runs
    by_id = {run.id: run for run in runs}
    unknown = [i for i in run_ids if i not in by_id]
    if unknown:
        raise ScoringProblem(f"run {unknown[0]} is not a completed training run", field="runs")
    return [by_id[i] for i in dict.fromkeys(run_ids)]


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
# Building the report


class _RowSpec(NamedTuple):
    key: str
    stats: str  # which of the job's statistics the row shows
    name: str
    kind: str
    detail: str


@dataclass
class _Job:
    """Rows that are scored in one pass, their cache key and how to score them."""

    rows: list[_RowSpec]
    cache_key: dict[str, Any]
    frames: int  # frames it will score, for progress (0 when unknown)
    score: Callable[[Callable[[int], None]], Scored]


def build_report(
    *,
    run_ids: Sequence[int] | None = None,
    study_ids: Sequence[int] | None = None,
    baselines: bool = True,
    thresholds: int = DEFAULT_THRESHOLDS,
    per_image: bool = False,
    use_cache: bool = True,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
    exclude_failed_checks: bool = False,
    by_condition: bool = False,
) -> Report:
    """Score the chosen runs, the baselines and the chosen studies' participants.

    Args:
        run_ids: Completed training runs to include; None for all of them.
        study_ids: Studies whose participants to include; None for all.
        baselines: Include AOP, the centre prior and saliency.
        thresholds: The number T of thresholds ``k / (T + 1)``.
        per_image: Average P and R over frames instead of pooling counts.
        use_cache: Read statistics cached by an earlier report with the
            same inputs (they are written either way).
        on_start: Called once with the number of frames to score.
        on_progress: Called with the number of frames just scored.
        exclude_failed_checks: Leave out participants who failed a
            comprehension or attention (catch trial) check.
        by_condition: Split the human rows by the studies' conditions
            (ordered and named by condition).

    Returns:
        The :class:`Report`. A source whose maps cannot be scored (say, a
        run whose predictions do not match the frames' sizes) becomes a note
        instead of a row, so the other rows still show.

    Raises:
        ScoringProblem: naming ``runs``, ``studies`` or ``thresholds``.

    Example::

        report = build_report(run_ids=[3], study_ids=[1])
        print(report.to_table())
    """
    try:
        threshold_values(thresholds)
    except ValueError as exc:
        raise ScoringProblem(str(exc), field="thresholds") from None
    runs = _choose_runs(run_ids)
    chosen_studies = _choose_studies(study_ids)
    truth = sources.load_truth()
    notes: list[str] = []
    jobs = [_run_job(run, truth, thresholds) for run in runs]
    if baselines and truth.frames:
        jobs.append(_baseline_job(truth, thresholds))
    jobs += _participant_jobs(
        chosen_studies, truth, thresholds, notes, exclude_failed_checks=exclude_failed_checks, by_condition=by_condition
    )
    rows = _rows(
        jobs,
        thresholds=thresholds,
        per_image=per_image,
        use_cache=use_cache,
        on_start=on_start,
        on_progress=on_progress,
        notes=notes,
    )
    activities = sorted({a for r in rows for a in r.cells})
    return Report(activities=activities, rows=rows, thresholds=thresholds, per_image=per_image, notes=notes)


def _rows(
    jobs: list[_Job],
    *,
    thresholds: int,
    per_image: bool,
    use_cache: bool,
    on_start: Callable[[int], None] | None,
    on_progress: Callable[[int], None] | None,
    notes: list[str],
) -> list[Row]:
    """The jobs' rows, from cached statistics or scored now (and cached); what went wrong goes to ``notes``."""
    cached = [(cache.cache_path(job.cache_key), job) for job in jobs]
    cached = [(path, job, cache.read_cached(path, thresholds) if use_cache else None) for path, job in cached]
    if on_start is not None:
        on_start(sum(job.frames for _, job, got in cached if got is None))
    rows = []
    for path, job, got in cached:
        if got is None:
            try:
                got = job.score(on_progress or (lambda n: None))
            except ValueError as exc:  # a map or mask that egonet.metrics refuses
                notes.append(f"{job.rows[0].name} could not be scored: {exc}")
                continue
            cache.write_cached(path, *got)
        stats, job_notes = got
        notes += job_notes
        for spec in job.rows:
            if not stats.get(spec.stats):
                if not job_notes:  # else the job has said why
                    notes.append(f"{spec.name} has no frames with a ground truth to score.")
                continue
            rows.append(_row(spec, stats[spec.stats], per_image=per_image))
    return rows


def _run_job(run: TrainingRun, truth: Truth, thresholds: int) -> _Job:
    # ``flask egonet predict`` may replace a run's held-out maps: they are part of the key.
    predictions = db.session.execute(
        db.select(func.count(), func.max(Prediction.id)).where(Prediction.run_id == run.id, Prediction.held_out.is_(True))
    ).one()
    return _Job(
        rows=[_RowSpec(f"run:{run.id}", "", sources.run_row_name(run), MODEL, f"{run.name}, {run.folds} folds")],
        cache_key={"run": run.id, "predictions": list(predictions), "truth": truth.fingerprint, "thresholds": thresholds},
        # Leave-one-activity-out holds every labelled frame out once.
        frames=len(truth.frames) if run.folds == "loao" else 0,
        score=lambda progress: sources.run_stats(run, truth, thresholds, progress),
    )


def _baseline_job(truth: Truth, thresholds: int) -> _Job:
    return _Job(
        rows=[_RowSpec(f"baseline:{key}", key, name, BASELINE, "") for key, name in BASELINE_NAMES.items()],
        cache_key={
            "baselines": {"aop_size": AOP_SIZE, "center_sigma": CENTER_SIGMA, "saliency": SALIENCY,
                          "gbvs": sources.GBVS, "handled": sources.HANDLED},
            "truth": truth.fingerprint,
            "thresholds": thresholds,
        },
        frames=2 * len(truth.frames),  # the AOP pass, then the scoring pass
        score=lambda progress: sources.baseline_stats(truth, thresholds, progress),
    )


def _participant_jobs(
    study_ids: list[int], truth: Truth, thresholds: int, notes: list[str], *, exclude_failed_checks: bool, by_condition: bool
) -> list[_Job]:
    chosen = sources.human_participants(study_ids, exclude_failed_checks=exclude_failed_checks, by_condition=by_condition)
    participants = [person for person, _ in chosen]
    if exclude_failed_checks:
        left_out = len(studies_service.study_participants(study_ids)) - len(participants)
        if left_out:
            notes.append(f"{left_out} participant{'s' if left_out != 1 else ''} who failed a check left out.")
    # Answers are never changed once given, so their number and the last
    # answered trial tell whether a participant's cached scores still hold.
    answered = {
        pid: (n, last)
        for pid, n, last in db.session.execute(
            db.select(Trial.participant_id, func.count(), func.max(Trial.id))
            .where(Trial.participant_id.in_([p.id for p in participants]), Trial.outcome.in_(ANSWERED))
            .group_by(Trial.participant_id)
        ).all()
    }
    jobs = []
    for person, condition in chosen:
        n, last = answered.get(person.id, (0, None))
        name = person.label if len(study_ids) == 1 else f"{person.label} (study {person.study_id})"
        if condition is not None:
            name = f"{name} [{condition or 'no condition'}]"
        if n == 0:
            notes.append(f"{name} has no answered trials yet.")
            continue
        jobs.append(
            _Job(
                rows=[_RowSpec(f"participant:{person.id}", "", name, HUMAN, f"{person.study.name}, participant {person.number}")],
                cache_key={"participant": person.id, "answered": [n, last], "truth": truth.fingerprint, "thresholds": thresholds},
                frames=n,
                score=lambda progress, person=person: sources.participant_stats(person, truth, thresholds, progress),
            )
        )
    return jobs


def _row(spec: _RowSpec, stats: Stats, *, per_image: bool) -> Row:
    def scored(acc: ScoreAccumulator) -> tuple[Cell, Curve]:
        s = acc.score(per_image=per_image)
        best = int(np.argmax(s.f))
        curve = Curve(tuple(np.round(s.precision, 5).tolist()), tuple(np.round(s.recall, 5).tolist()), best)
        return Cell(s.max_f, None if spec.kind == HUMAN else s.ap, s.n_maps), curve

    cells, curves = {}, {}
    pooled = ScoreAccumulator(thresholds=next(iter(stats.values())).thresholds)
    for activity in sorted(stats):
        cells[activity], curves[activity] = scored(stats[activity])
        pooled.merge(stats[activity])
    overall, curves[ALL] = scored(pooled)
    return Row(spec.key, spec.name, spec.kind, spec.detail, cells, overall, curves)
