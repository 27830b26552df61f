"""Per-epoch history of runs: written as each epoch ends, read by the Training page's charts.

The job records every fold's epochs as ``TrainingEpoch`` rows the moment
the engine hands over a complete record (``egonet.train.fit``'s
``on_epoch``), and once more when the fold ends (a run that continues a
checkpoint inherits that checkpoint's earlier epochs then). A record is
never changed in place: writing an epoch again replaces its row by a new
one, so a poller that asks for rows after the last id it saw
(``epoch_rows(after=...)``) gets every change, in bounded pages.
"""

from collections.abc import Iterable, Sequence
from typing import Any

from sqlalchemy import delete

from app.extensions import db
from app.models.training import FINAL_STATUSES, Checkpoint, TrainingEpoch, TrainingRun
from app.services.training.control import TrainingProblem

HISTORY_KEYS = ("lr", "train_loss", "loss", "max_f", "ap")
MAX_COMPARED_RUNS = 12
"""Most runs one chart request may ask for."""
PAGE_ROWS = 2000
"""Most epoch rows one chart request returns (the poller asks again for the rest)."""


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def record_epochs(run_id: int, fold: str, records: Iterable[dict]) -> None:
    """Write (or replace) epoch records of a fold; the caller commits."""
    rows = {int(r["epoch"]): r for r in records if isinstance(r.get("epoch"), int)}
    if not rows:
        return
    db.session.execute(
        delete(TrainingEpoch).where(
            TrainingEpoch.run_id == run_id, TrainingEpoch.fold == fold, TrainingEpoch.epoch.in_(list(rows))
        )
    )
    db.session.add_all(
        TrainingEpoch(run_id=run_id, fold=fold, epoch=epoch, **{k: _number(r.get(k)) for k in HISTORY_KEYS})
        for epoch, r in sorted(rows.items())
    )


def parse_run_ids(text: str, *, field: str = "runs") -> list[int]:
    """Run ids from ``"3,5,8"`` (at most ``MAX_COMPARED_RUNS``), in the order given, without repeats.

    Raises:
        TrainingProblem: 400 naming ``field`` when an id is not a number or there are too many.
    """
    try:
        ids = list(dict.fromkeys(int(x) for x in text.split(",") if x.strip()))
    except ValueError:
        raise TrainingProblem(f"{field} must be run ids separated by commas", field=field) from None
    if len(ids) > MAX_COMPARED_RUNS:
        raise TrainingProblem(f"compare at most {MAX_COMPARED_RUNS} runs at once", field=field)
    if any(not 0 < i < 2**31 for i in ids):
        raise TrainingProblem(f"{field}: no run has such an id", field=field)
    return ids


def chart_data(run_ids: Sequence[int], *, after: int = 0) -> dict[str, Any]:
    """What a chart needs of some runs: each run's status and folds, and its epoch rows after id ``after``.

    Returns:
        ``{"runs": [{id, name, status, active, folds: {fold: {aop_max_f, max_f, epochs}}}],
        "epochs": [{id, run, fold, epoch, lr, train_loss, loss, max_f, ap}], "after": last id,
        "more": whether rows are left}``, at most ``PAGE_ROWS`` rows, oldest first. Unknown
        ids are left out (a run deleted meanwhile disappears from the chart).
    """
    runs = db.session.execute(db.select(TrainingRun).where(TrainingRun.id.in_(list(run_ids)))).scalars().all()
    by_id = {run.id: run for run in runs}
    found = [by_id[i] for i in run_ids if i in by_id]
    rows = db.session.execute(
        db.select(TrainingEpoch)
        .where(TrainingEpoch.run_id.in_([r.id for r in found]), TrainingEpoch.id > after)
        .order_by(TrainingEpoch.id)
        .limit(PAGE_ROWS + 1)
    ).scalars().all()
    more = len(rows) > PAGE_ROWS
    rows = rows[:PAGE_ROWS]
    return {
        "runs": [_run_summary(run) for run in found],
        "epochs": [
            {"id": r.id, "run": r.run_id, "fold": r.fold, "epoch": r.epoch, **{k: getattr(r, k) for k in HISTORY_KEYS}}
            for r in rows
        ],
        "after": rows[-1].id if rows else after,
        "more": more,
    }


def _run_summary(run: TrainingRun) -> dict[str, Any]:
    checkpoints = db.session.execute(db.select(Checkpoint).where(Checkpoint.run_id == run.id)).scalars()
    return {
        "id": run.id,
        "name": run.name,
        "status": run.status.value,
        "active": run.status not in FINAL_STATUSES,
        "epochs": run.epochs,
        "folds": {
            c.fold: {"aop_max_f": _number(c.metrics.get("aop_max_f")), "max_f": _number(c.metrics.get("max_f")), "epochs": c.epochs}
            for c in checkpoints
        },
    }


def runs_with_history(run_ids: Iterable[int]) -> set[int]:
    """Which of these runs have at least one epoch recorded."""
    ids = list(run_ids)
    if not ids:
        return set()
    query = db.select(TrainingEpoch.run_id).where(TrainingEpoch.run_id.in_(ids)).group_by(TrainingEpoch.run_id)
    return set(db.session.execute(query).scalars())

