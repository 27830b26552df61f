"""The authors' released models as runs: import a ``.caffemodel``, convert it, keep its checkpoint.

A release becomes a ``TrainingRun`` whose ``folds`` is ``released`` (it was
not trained here, so every frame is held out from it) with one
``Checkpoint`` (fold ``released``) in the project's format, so
``flask egonet predict``, the frame viewer, the Scores page and Suggest use
it like a trained run. ``register_release`` checks the file (its layers and
shapes are read, not its weights: instant even for 550 MB) and records the
run, queued; ``convert_release`` (the worker's ``import_weights`` job, or
``flask egonet import-weights`` in the foreground) copies the weights into
the model, writes ``run-<id>/released.pt`` and marks the run done, with
progress on the row as training runs have.

The Training page uploads a file in chunks (``start_upload``,
``write_chunk``, ``finish_upload``): each request carries at most
``CHUNK_BYTES``, the file grows in ``CHECKPOINT_ROOT/uploads`` up to the
size announced (at most ``WEIGHTS_MAX_BYTES``), and is never held in memory.
The worker deletes the upload once converted; an upload left unfinished is
removed a day later.
"""

import json
import re
import secrets
import time
from collections.abc import Callable
from pathlib import Path

from flask import current_app
from sqlalchemy import update

from app.extensions import db
from app.models import User, utcnow
from app.models.training import Checkpoint, FoldsMode, RunStatus, TrainingRun
from app.queue import enqueue
from app.services.training.control import TrainingProblem, checkpoint_root, claim_run
from egonet.errors import Cancelled, EgonetError

CHUNK_BYTES = 8 * 1024 * 1024
"""The most one upload request may carry (well under ``MAX_CONTENT_LENGTH``)."""
DEFAULT_MAX_BYTES = 1024**3
"""``WEIGHTS_MAX_BYTES`` unless configured: the RGB+DHG release is 554 MB."""
MAX_PENDING_UPLOADS = 4
STALE_UPLOAD_S = 24 * 3600
PROGRESS_INTERVAL_S = 1.0
_TOKEN = re.compile(r"[0-9a-f]{32}")


def uploads_root() -> Path:
    return checkpoint_root() / "uploads"


def max_bytes() -> int:
    return int(current_app.config.get("WEIGHTS_MAX_BYTES", DEFAULT_MAX_BYTES))


# --------------------------------------------------------------------------- runs


def register_release(
    path: Path, *, name: str | None = None, size: tuple[int, int] | None = None, created_by: User | None = None,
    filename: str | None = None, releases=None,
) -> TrainingRun:
    """Check that ``path`` is one of the authors' releases and record its run, queued for conversion.

    Args:
        path: The ``.caffemodel`` (a file the caller keeps until converted).
        name: The run's name (default: the release and the file's name).
        size: ``(H, W)`` frames are run at; the release's deploy size 481x641 by default.
        created_by: Who imports it.
        filename: The file's name as the user knows it (an upload's), for messages and the record.
        releases: The releases to accept (``egonet.caffe.RELEASES``; tests pass small ones).

    Raises:
        TrainingProblem: ``file``: not a release (the one-line reason), or ``size``/``name``.
    """
    import torch

    from egonet.caffe import DEPLOY_SIZE, RELEASES, identify_release, read_caffemodel

    filename = filename or path.name
    size = DEPLOY_SIZE if size is None else tuple(size)
    if len(size) != 2 or not all(isinstance(s, int) and 8 <= s <= 4096 for s in size):
        raise TrainingProblem(f"size must be two sides of 8-4096 pixels, got {size!r}", field="size")
    try:
        release = identify_release(read_caffemodel(path, name=filename), releases=releases or RELEASES, path=filename)
    except EgonetError as exc:
        raise TrainingProblem(exc.message, field="file") from None
    name = (name or "").strip() or f"released {release.key.upper()} model ({filename})"
    if len(name) > 200:
        raise TrainingProblem("name must have at most 200 characters", field="name")
    with torch.device("meta"):  # the options only: instant
        options = dict(release.build().config.options)
    run = TrainingRun(
        name=name, model_name=release.model, model_options=options, folds=FoldsMode.RELEASED, epochs=0,
        device="cpu", seed=0, status=RunStatus.QUEUED, message=f"queued: reading {filename}",
        config={"released": {"release": release.key, "title": release.title, "file": filename,
                             "bytes": path.stat().st_size, "height": size[0], "width": size[1]}},
        created_by=created_by,
    )
    db.session.add(run)
    db.session.commit()
    return run


def convert_release(run_id: int, path: Path, *, delete: bool = False, releases=None,
                    on_progress: Callable[[int, int], None] | None = None) -> TrainingRun:
    """The job: the release's weights into a checkpoint, its ``Checkpoint`` row, the run done.

    Runs in the worker (``import_weights`` of ``app.tasks``) or in the
    foreground (``flask egonet import-weights``). Progress goes to the run's
    row at most once a second; a cancelled run stops at its next report.

    Args:
        run_id: A run made by :func:`register_release`.
        path: Its ``.caffemodel``.
        delete: Remove ``path`` afterwards, whatever happens (an upload).
        releases: As given to :func:`register_release`.
        on_progress: Also called with ``(bytes done, file size)`` (the CLI's bar).
    """
    from egonet.caffe import RELEASES, checkpoint_from_caffemodel
    from egonet.checkpoint import save_checkpoint

    run = db.session.get(TrainingRun, run_id)
    if run is None:
        raise TrainingProblem(f"no training run with id {run_id}")
    try:
        if not claim_run(run, "reading the weights"):
            return run
        info = run.config["released"]
        reporter = _Reporter(run.id, on_progress)
        state = checkpoint_from_caffemodel(path, size=(info["height"], info["width"]), releases=releases or RELEASES,
                                           progress=reporter, name=info["file"])
        relative = Path(f"run-{run.id}") / "released.pt"
        reporter.say("writing the checkpoint", 0.95)
        save_checkpoint(checkpoint_root() / relative, state)
        db.session.add(Checkpoint(run_id=run.id, fold="released", path=relative.as_posix(), epochs=0,
                                  metrics={"released": state["released"]}, test_frame_ids=[]))
        run.config = dict(run.config) | {"released": info | {"sha256": state["released"]["sha256"]}}
        db.session.execute(
            update(TrainingRun).where(TrainingRun.id == run.id, TrainingRun.status == RunStatus.RUNNING)
            .values(status=RunStatus.DONE, progress=1.0, finished_at=utcnow(), eta_s=None,
                    message=f"done: {state['released']['title']}, sha256 {state['released']['sha256'][:12]}")
        )
        db.session.commit()
    except Cancelled:
        db.session.rollback()
    except Exception as exc:
        db.session.rollback()
        message = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        db.session.execute(
            update(TrainingRun).where(TrainingRun.id == run_id, TrainingRun.status.in_([RunStatus.QUEUED, RunStatus.RUNNING]))
            .values(status=RunStatus.FAILED, finished_at=utcnow(), eta_s=None, message=f"failed: {message}"[:2000])
        )
        db.session.commit()
        if not isinstance(exc, EgonetError | TrainingProblem):
            raise
    finally:
        if delete:
            Path(path).unlink(missing_ok=True)
    db.session.refresh(run)
    return run


def import_in_foreground(path: Path, *, name: str | None = None, size: tuple[int, int] | None = None,
                         on_progress: Callable[[int, int], None] | None = None) -> TrainingRun:
    """``flask egonet import-weights``: register and convert here; the file stays where it is."""
    run = register_release(path, name=name, size=size)
    return convert_release(run.id, path, on_progress=on_progress)


class _Reporter:
    """The loader's progress to the run's row (at most once a second), and cancellation back."""

    def __init__(self, run_id: int, on_progress: Callable[[int, int], None] | None):
        self.run_id, self.on_progress, self.last = run_id, on_progress, 0.0

    def __call__(self, done: int, total: int) -> None:
        if self.on_progress is not None:
            self.on_progress(done, total)
        if time.monotonic() - self.last >= PROGRESS_INTERVAL_S or done >= total:
            self.say(f"reading the weights: {done / 2**20:,.0f} of {total / 2**20:,.0f} MiB", 0.9 * done / max(total, 1))

    def say(self, message: str, fraction: float) -> None:
        self.last = time.monotonic()
        status = db.session.execute(
            update(TrainingRun).where(TrainingRun.id == self.run_id)
            .values(progress=fraction, message=message, updated_at=utcnow()).returning(TrainingRun.status)
        ).scalar_one()
        db.session.commit()
        if status == RunStatus.CANCELLED:
            raise Cancelled


# --------------------------------------------------------------------------- uploads


def start_upload(*, filename: str, size: int, user: User) -> dict:
    """Announce an upload of ``size`` bytes; returns ``{"upload": token, "chunk_bytes": CHUNK_BYTES}``.

    Raises:
        TrainingProblem: ``filename`` not a ``.caffemodel``, ``size`` over
            ``WEIGHTS_MAX_BYTES`` (413), or too many uploads under way (409).
    """
    if not filename.lower().endswith(".caffemodel"):
        raise TrainingProblem(f"{filename!r} is not a .caffemodel file", field="filename")
    if size > max_bytes():
        raise TrainingProblem(
            f"the file has {size:,} bytes, more than the {max_bytes():,} allowed (WEIGHTS_MAX_BYTES)",
            field="size", status=413,
        )
    root = uploads_root()
    root.mkdir(parents=True, exist_ok=True)
    _remove_stale(root)
    if len(list(root.glob("*.json"))) >= MAX_PENDING_UPLOADS:
        raise TrainingProblem(f"{MAX_PENDING_UPLOADS} uploads are under way already: finish or cancel one", status=409)
    token = secrets.token_hex(16)
    (root / f"{token}.part").write_bytes(b"")
    meta = {"filename": Path(filename).name, "size": size, "user_id": user.id, "created": time.time()}
    (root / f"{token}.json").write_text(json.dumps(meta))
    return {"upload": token, "chunk_bytes": CHUNK_BYTES}


def write_chunk(token: str, *, offset: int, stream, length: int | None, user: User) -> int:
    """Append one chunk at ``offset`` (the bytes received so far); returns the new total.

    A chunk sent again after a lost answer (its offset is already behind
    the file's end) overwrites the same bytes.

    Raises:
        TrainingProblem: 404 unknown upload; 411 no length; 413 a chunk over
            ``CHUNK_BYTES`` or past the size announced; 409 an offset ahead
            of the bytes received (the answer says how many).
    """
    meta, part = _upload(token, user)
    received = part.stat().st_size
    if length is None:
        raise TrainingProblem("send each chunk with a Content-Length", status=411)
    if length > CHUNK_BYTES or offset + length > meta["size"]:
        raise TrainingProblem(f"a chunk may hold {CHUNK_BYTES:,} bytes and end at {meta['size']:,} at most",
                              field="body", status=413)
    if offset > received:
        raise TrainingProblem(f"offset {offset} is past the {received} bytes received", field="offset", status=409,
                              received=received)
    with part.open("r+b") as fh:
        fh.seek(offset)
        left = length
        while left:
            data = stream.read(min(left, 1 << 20))
            if not data:
                raise TrainingProblem(f"the chunk ended after {length - left} of {length} bytes", field="body")
            fh.write(data)
            left -= len(data)
        fh.truncate(offset + length)
    return offset + length


def finish_upload(token: str, *, name: str | None, size: tuple[int, int] | None, user: User) -> TrainingRun:
    """The whole file is here: check it is a release, record its run and queue the conversion.

    Raises:
        TrainingProblem: 404 unknown upload; 409 bytes missing; 400 not a
            release (``file``; the upload is removed).
    """
    meta, part = _upload(token, user)
    received = part.stat().st_size
    if received != meta["size"]:
        raise TrainingProblem(f"{received:,} of {meta['size']:,} bytes received: send the rest first", status=409,
                              received=received)
    path = part.with_name(f"{token}-{meta['filename']}")
    part.rename(path)
    (part.with_suffix(".json")).unlink(missing_ok=True)
    run = None
    try:
        run = register_release(path, name=name, size=size, created_by=user, filename=meta["filename"])
    finally:
        if run is None:  # refused, or anything unforeseen: the upload goes
            path.unlink(missing_ok=True)
    enqueue("import_weights", run.id, str(path))
    return run


def cancel_upload(token: str, *, user: User) -> None:
    """Remove an unfinished upload."""
    _, part = _upload(token, user)
    part.unlink(missing_ok=True)
    part.with_suffix(".json").unlink(missing_ok=True)


def _upload(token: str, user: User) -> tuple[dict, Path]:
    root = uploads_root()
    meta_path = root / f"{token}.json"
    if not _TOKEN.fullmatch(token) or not meta_path.is_file():
        raise TrainingProblem(f"no upload {token[:40]!r} under way (finished, cancelled or older than a day)", status=404)
    meta = json.loads(meta_path.read_text())
    if meta["user_id"] != user.id:
        raise TrainingProblem("this upload is another user's", status=404)
    return meta, root / f"{token}.part"


def _remove_stale(root: Path) -> None:
    """Unfinished uploads older than a day."""
    cutoff = time.time() - STALE_UPLOAD_S
    for meta in root.glob("*.json"):
        if meta.stat().st_mtime < cutoff:
            meta.with_suffix(".part").unlink(missing_ok=True)
            meta.unlink(missing_ok=True)
