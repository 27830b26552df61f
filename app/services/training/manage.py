"""Managing runs: rename and tag them, download their files, delete them.

* ``edit_run``: admins rename and tag a run. Each edit carries the
  ``version`` it was based on; an edit against a newer version is refused
  (409), so two admins cannot overwrite each other. The worker's progress
  reports never change ``version``.
* ``checkpoint_file`` / ``run_config``: what the downloads serve.
* ``deletion_plan`` / ``delete_run``: a finished, failed or cancelled run
  goes with everything it made: its checkpoints (rows and files), its
  predictions (rows, their media files unless another row shares them, and
  their cached overlays), its epoch history; annotations it proposed into
  keep their masks and lose the reference. The rows go in one transaction,
  which refuses a queued or running run; files go after it commits (a crash
  in between leaves orphans that ``flask egonet media-check
  --remove-orphans`` removes, never a row without its file).
"""

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import delete, or_, select, update

from app.extensions import db
from app.models import Annotation, Instance
from app.models.training import FINAL_STATUSES, Checkpoint, Prediction, TrainingEpoch, TrainingRun
from app.services import media
from app.services.storage import store as storage
from app.services.training import files
from app.services.training.control import TrainingProblem

MAX_TAGS = 12
TAG_PATTERN = re.compile(r"[\w][\w .+-]{0,39}")


# --------------------------------------------------------------------------- name and tags


def parse_tags(text: str) -> list[str]:
    """Tags from ``"baseline, lite 160"``: trimmed, repeats dropped, in order.

    Raises:
        TrainingProblem: naming ``tags``.
    """
    tags = list(dict.fromkeys(t.strip() for t in (text or "").split(",") if t.strip()))
    bad = [t for t in tags if not TAG_PATTERN.fullmatch(t)]
    if bad:
        raise TrainingProblem(
            f"tag {bad[0][:50]!r}: up to 40 letters, digits, spaces or _ . + - (starting with a letter or digit)",
            field="tags",
        )
    if len(tags) > MAX_TAGS:
        raise TrainingProblem(f"at most {MAX_TAGS} tags per run", field="tags")
    return tags


def edit_run(run: TrainingRun, *, name: str, tags: list[str], version: int) -> TrainingRun:
    """Rename and tag a run, if nobody else changed it since ``version``.

    Raises:
        TrainingProblem: 400 for an empty or long name; 409 when the run's
            version is no longer ``version`` (the run is reloaded: the caller
            shows the newer values).
    """
    name = (name or "").strip()
    if not name:
        raise TrainingProblem("a run needs a name", field="name")
    if len(name) > 200:
        raise TrainingProblem("name must have at most 200 characters", field="name")
    changed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.version == version)
        .values(name=name, tags=list(tags), version=TrainingRun.version + 1)
        .execution_options(synchronize_session=False)
    ).rowcount
    db.session.commit()
    db.session.refresh(run)
    if not changed:
        raise TrainingProblem(
            f"run {run.id} was changed by someone else meanwhile (now {run.name!r}, tags {', '.join(run.tags) or 'none'}): "
            "look at their change and edit again",
            field="version",
            status=409,
        )
    return run


def all_tags() -> list[str]:
    """Every tag in use, sorted (the Training page's filter)."""
    tags: set[str] = set()
    for run_tags in db.session.execute(select(TrainingRun.tags)).scalars():
        tags.update(run_tags or [])
    return sorted(tags, key=str.lower)


def runs_tagged(tag: str | None, *, limit: int = 100) -> list[TrainingRun]:
    """The newest runs first, only those with ``tag`` when given."""
    query = select(TrainingRun).order_by(TrainingRun.id.desc())
    if not tag:
        return list(db.session.execute(query.limit(limit)).scalars())
    # Tags are a JSON list: filtered here, not in SQL, so SQLite and PostgreSQL agree.
    return [run for run in db.session.execute(query).scalars() if tag in (run.tags or [])][:limit]


# --------------------------------------------------------------------------- downloads


def checkpoint_file(checkpoint: Checkpoint) -> tuple[Path, str]:
    """The checkpoint's file on this host (a bucket's: this host's checked copy) and the name to download
    it as (``run-3-cooking-e10.pt``).

    Raises:
        TrainingProblem: 404 when the file is gone from storage.
    """
    try:
        path = files.local_path(checkpoint.path)
    except FileNotFoundError:
        path = None
    if path is None or not path.is_file():
        raise TrainingProblem(f"checkpoint {checkpoint.id}'s file {checkpoint.path} is missing on the server", status=404)
    slug = re.sub(r"[^A-Za-z0-9_.-]+", "-", checkpoint.fold).strip("-") or "fold"
    return path, f"run-{checkpoint.run_id}-{slug}-e{checkpoint.epochs}.pt"


def run_config(run: TrainingRun) -> dict[str, Any]:
    """A run's configuration as one JSON document: the request, the resolved training config, and the
    engine's ``config.json`` (device, world size, torch version, folds) when training has started."""
    try:
        engine = json.loads(files.read(f"{files.run_folder(run.id)}/config.json"))
    except (FileNotFoundError, ValueError):
        engine = None
    return {
        "run": run.id,
        "name": run.name,
        "tags": list(run.tags or []),
        "model": run.model_name,
        "model_options": run.model_options,
        "folds": run.folds.value,
        "epochs": run.epochs,
        "device": run.device,
        "seed": run.seed,
        "status": run.status.value,
        "config": run.config,
        "engine": engine,
        "checkpoints": [
            {"id": c.id, "fold": c.fold, "file": c.path, "epochs": c.epochs, "test_frame_ids": c.test_frame_ids,
             "metrics": {k: v for k, v in c.metrics.items() if k != "history"}}
            for c in run.checkpoints
        ],
        "created_at": run.created_at.isoformat(),
    }


# --------------------------------------------------------------------------- deleting


@dataclass(frozen=True)
class DeletionPlan:
    """What deleting a run removes (the confirmation page lists it)."""

    run: TrainingRun
    checkpoints: int
    checkpoint_bytes: int
    predictions: int
    media_files: int
    epochs: int
    proposals: int

    @property
    def allowed(self) -> bool:
        return self.run.status in FINAL_STATUSES


def _prediction_paths(run_id: int) -> set[str]:
    return set(db.session.execute(select(Prediction.path).where(Prediction.run_id == run_id)).scalars())


def _shared_paths(paths: set[str], run_id: int) -> set[str]:
    """Which of these media paths a row outside the run still refers to (content-addressed files can be shared)."""
    shared: set[str] = set()
    chunk = sorted(paths)
    for start in range(0, len(chunk), 500):
        part = chunk[start : start + 500]
        for table in db.metadata.sorted_tables:
            for column in table.columns:
                if not column.info.get("media"):
                    continue
                query = select(column).where(column.in_(part))
                if table.name == Prediction.__tablename__:
                    query = query.where(table.c.run_id != run_id)
                shared.update(db.session.execute(query).scalars())
    return shared


def _proposal_refs(run_id: int, checkpoint_ids: list[int]):
    """The annotation and instance columns that name this run or its checkpoints as proposer
    (its pending proposals first lose their mark: they become ordinary instances)."""
    yield Instance, "proposal_source", Instance.proposed_by_run_id == run_id
    for model in (Annotation, Instance):
        yield model, "proposed_by_run_id", model.proposed_by_run_id == run_id
        yield model, "proposed_by_checkpoint_id", model.proposed_by_checkpoint_id.in_(checkpoint_ids)


def deletion_plan(run: TrainingRun) -> DeletionPlan:
    checkpoints = list(run.checkpoints)
    size = sum(size for _, size, _ in files.listing(files.run_folder(run.id)))
    paths = _prediction_paths(run.id)
    count = db.session.execute(select(db.func.count(Prediction.id)).where(Prediction.run_id == run.id)).scalar_one()
    epochs = db.session.execute(select(db.func.count(TrainingEpoch.id)).where(TrainingEpoch.run_id == run.id)).scalar_one()
    proposals = sum(
        db.session.execute(
            select(db.func.count()).select_from(model).where(
                or_(model.proposed_by_run_id == run.id, model.proposed_by_checkpoint_id.in_([c.id for c in checkpoints]))
            )
        ).scalar_one()
        for model in (Annotation, Instance)
    )
    return DeletionPlan(run, len(checkpoints), size, count, len(paths - _shared_paths(paths, run.id)), epochs, proposals)


def delete_run(run: TrainingRun) -> dict[str, int]:
    """Delete a finished, failed or cancelled run and everything it made (see the module docstring).

    Returns:
        How many ``predictions``, ``checkpoints``, ``media_files`` and ``epochs`` went.

    Raises:
        TrainingProblem: 409 while the run is queued or running (cancel it first).
    """
    run_id = run.id
    # First a guarded write on the run's row: it takes the row's lock (the database's write lock
    # on SQLite), so the run cannot be resumed between this check and the deletion.
    claimed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run_id, TrainingRun.status.in_(list(FINAL_STATUSES)))
        .values(version=TrainingRun.version + 1)
        .execution_options(synchronize_session=False)
    ).rowcount
    if not claimed:
        db.session.rollback()
        db.session.refresh(run)
        raise TrainingProblem(f"run {run_id} is {run.status.value}: cancel it first, then delete it", status=409)
    checkpoint_ids = list(db.session.execute(select(Checkpoint.id).where(Checkpoint.run_id == run_id)).scalars())
    paths = _prediction_paths(run_id)
    # Children first and explicitly: SQLite enforces no foreign keys here, PostgreSQL would cascade.
    for model, column, where in _proposal_refs(run_id, checkpoint_ids):
        db.session.execute(update(model).where(where).values({column: None}).execution_options(synchronize_session=False))
    counts = {}
    for name, model in (("predictions", Prediction), ("epochs", TrainingEpoch), ("checkpoints", Checkpoint)):
        counts[name] = db.session.execute(
            delete(model).where(model.run_id == run_id).execution_options(synchronize_session=False)
        ).rowcount
    db.session.execute(delete(TrainingRun).where(TrainingRun.id == run_id).execution_options(synchronize_session=False))
    unshared = paths - _shared_paths(paths, run_id)
    db.session.commit()
    db.session.expunge_all()
    _remove_files(run_id, unshared)
    counts["media_files"] = len(unshared)
    return counts


def _remove_files(run_id: int, paths: set[str]) -> None:
    """After the commit: the run's media, their cached overlays, and its checkpoints in storage."""
    cache = media.derived_path("predictions")
    for rel in paths:
        storage().delete(media.AREA + rel)
        stem = Path(rel).stem
        for cached in cache.glob(f"*-{stem}*"):
            cached.unlink(missing_ok=True)
    files.delete_folder(files.run_folder(run_id))
