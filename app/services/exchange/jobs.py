"""Exports asked for on the Label page: small ones answer at once, the rest are built by the worker.

An export fits a request when it copies no images and its masks hold at
most ``EXPORT_INLINE_MAX_PIXELS`` pixels (the frames' pixels, once per
exported annotation); anything bigger is an ``ExportJob`` that ``flask
egonet worker`` writes as a zip to storage (``exports/export-<id>.zip``,
``app.services.storage``, so any host serves the download) with its progress
on the row, so no request does work whose size the person controls. A
person has at most ``EXPORT_MAX_PENDING`` exports waiting or under way;
the ``EXPORT_KEEP`` most recent finished ones are kept, older ones (row
and zip) go when a new one is asked for.
"""

import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from flask import current_app
from sqlalchemy import update

from app.extensions import db
from app.models import User, utcnow
from app.models.exports import ExportJob, ExportStatus
from app.queue import enqueue
from app.services.exchange.selection import ExchangeProblem, ExportOptions, Plan
from app.services.exchange.writing import write_zip
from app.services.storage import StorageUnavailable
from app.services.storage import store as storage

ACTIVE = (ExportStatus.QUEUED, ExportStatus.RUNNING)
# The worker writes its progress at most this often (seconds).
PROGRESS_EVERY_S = 0.5


AREA = "exports/"


def fits_a_request(options: ExportOptions, plan: Plan) -> bool:
    """Whether the export is small enough to build inside the request that asks for it."""
    return not options.images and plan.pixels <= current_app.config["EXPORT_INLINE_MAX_PIXELS"]


def get_export(export_id: int) -> ExportJob:
    job = db.session.get(ExportJob, export_id)
    if job is None:
        raise ExchangeProblem(f"no export {export_id}", status=404, field="export_id")
    return job


def recent_exports(*, limit: int = 10) -> list[ExportJob]:
    return list(db.session.execute(db.select(ExportJob).order_by(ExportJob.id.desc()).limit(limit)).scalars())


def queue_export(options: ExportOptions, user: User, plan: Plan) -> ExportJob:
    """Record an export for the worker and queue it; returns the row (queued).

    Raises:
        ExchangeProblem: 429 when ``user`` has ``EXPORT_MAX_PENDING`` exports
            waiting or under way already.
    """
    pending = db.session.execute(
        db.select(db.func.count(ExportJob.id)).where(ExportJob.requested_by_id == user.id, ExportJob.status.in_(ACTIVE))
    ).scalar_one()
    limit = current_app.config["EXPORT_MAX_PENDING"]
    if pending >= limit:
        raise ExchangeProblem(f"you have {pending} exports waiting or under way (at most {limit}): "
                              "wait for one to finish", status=429, field="export")
    _prune()
    job = ExportJob(requested_by=user, options=options.to_dict(), total=plan.frames)
    db.session.add(job)
    db.session.commit()
    enqueue("build_export", job.id)
    return job


def build_export(export_id: int) -> ExportJob:
    """The worker's job: write the export's zip, with its progress on the row.

    A job that is not queued any more (another worker took it) is left alone.

    Raises:
        Exception: whatever made it fail, after the row says so.
    """
    job = get_export(export_id)
    claimed = db.session.execute(
        update(ExportJob).where(ExportJob.id == job.id, ExportJob.status == ExportStatus.QUEUED)
        .values(status=ExportStatus.RUNNING, started_at=utcnow())
    ).rowcount
    db.session.commit()
    if not claimed:
        return job
    name = f"export-{job.id}.zip"
    try:
        # Built in a file on this host first (a zip's directory comes last; a bucket takes whole objects).
        spool = Path(current_app.config["CACHE_ROOT"])
        spool.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(suffix=".zip", dir=spool) as out:
            report = write_zip(out, ExportOptions.from_dict(job.options), on_start=_progress(job.id, total=True),
                               on_progress=_progress(job.id))
            out.flush()
            size = out.tell()
            storage().put_file(AREA + name, Path(out.name))
    except BaseException as exc:
        db.session.rollback()
        _finish(job.id, status=ExportStatus.FAILED, message=_failure(exc))
        raise
    _finish(job.id, status=ExportStatus.DONE, done=report.frames, total=report.frames,
            annotations=report.annotations, instances=report.instances, file_name=name, size_bytes=size)
    db.session.expire_all()
    return get_export(export_id)


def _failure(exc: BaseException) -> str:
    """What the export's page says went wrong (never the bucket's name: the log has it)."""
    if isinstance(exc, StorageUnavailable):
        return "file storage was unreachable; export again later"
    return str(exc) or type(exc).__name__


def _progress(export_id: int, *, total: bool = False) -> Callable[[int], None]:
    """A callback that writes the job's progress on its own connection (the export's session stays as it is)."""
    state = {"done": 0, "written": 0.0}

    def on_progress(n: int) -> None:
        if total:
            _update(export_id, total=n)
            return
        state["done"] += n
        if time.monotonic() - state["written"] >= PROGRESS_EVERY_S:
            state["written"] = time.monotonic()
            _update(export_id, done=state["done"])

    return on_progress


def _update(export_id: int, **values) -> None:
    with db.engine.begin() as conn:
        conn.execute(update(ExportJob).where(ExportJob.id == export_id).values(**values))


def _finish(export_id: int, **values) -> None:
    _update(export_id, finished_at=utcnow(), **values)


def export_file(job: ExportJob) -> Path:
    """The finished export's zip on this host's disk (a bucket's: this host's cached copy).

    Raises:
        ExchangeProblem: 409 while it is not done, 410 when its file is gone.
    """
    if job.status is not ExportStatus.DONE or not job.file_name:
        raise ExchangeProblem(f"export {job.id} is {job.status.value}, not ready to download", status=409,
                              field="export_id")
    try:
        return storage().local_path(AREA + job.file_name)
    except FileNotFoundError:
        raise ExchangeProblem(f"export {job.id}: its file is gone; export again", status=410, field="export_id") from None


def _prune() -> None:
    """Remove finished exports beyond the ``EXPORT_KEEP`` most recent, rows and files."""
    keep = current_app.config["EXPORT_KEEP"]
    finished = db.session.execute(
        db.select(ExportJob).where(ExportJob.status.not_in(ACTIVE)).order_by(ExportJob.id.desc()).offset(keep)
    ).scalars().all()
    for job in finished:
        if job.file_name:
            storage().delete(AREA + job.file_name)
        db.session.delete(job)
