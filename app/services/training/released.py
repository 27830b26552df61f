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
``CHUNK_BYTES``, stored as an object of its own under the storage key
``checkpoints/uploads/<token>/`` (so the chunks may reach different web hosts
behind a load balancer), up to the size announced (at most
``WEIGHTS_MAX_BYTES``); the file is never held in memory. On finishing, the
host that checks the file and the worker that converts it each put the
chunks together in their own cache. The worker deletes the upload once
converted; an upload left unfinished is removed a day later.
"""

import contextlib
import json
import os
import re
import secrets
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from flask import current_app
from sqlalchemy import update

from app.extensions import db
from app.models import User, utcnow
from app.models.training import Checkpoint, FoldsMode, RunStatus, TrainingRun
from app.queue import enqueue
from app.services.training import files
from app.services.training.control import TrainingProblem, claim_run, holding_lease
from egonet.errors import Cancelled, EgonetError

CHUNK_BYTES = 8 * 1024 * 1024
"""The most one upload request may carry (well under ``MAX_CONTENT_LENGTH``)."""
DEFAULT_MAX_BYTES = 1024**3
"""``WEIGHTS_MAX_BYTES`` unless configured: the RGB+DHG release is 554 MB."""
MAX_PENDING_UPLOADS = 4
STALE_UPLOAD_S = 24 * 3600
PROGRESS_INTERVAL_S = 1.0
_TOKEN = re.compile(r"[0-9a-f]{32}")
UPLOADS = "uploads"
"""Uploads in storage: ``checkpoints/uploads/<token>/`` holds the chunks, ``part-<offset>``, and
while the upload is under way its ``meta.json``."""
META = "meta.json"


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


def convert_release(run_id: int, path: Path, *, releases=None,
                    on_progress: Callable[[int, int], None] | None = None) -> TrainingRun:
    """The job: the release's weights into a checkpoint, its ``Checkpoint`` row, the run done.

    Runs in the worker (``import_weights`` of ``app.tasks``) or in the
    foreground (``flask egonet import-weights``). Progress goes to the run's
    row at most once a second; a cancelled run stops at its next report.

    Args:
        run_id: A run made by :func:`register_release`.
        path: Its ``.caffemodel``.
        releases: As given to :func:`register_release`.
        on_progress: Also called with ``(bytes done, file size)`` (the CLI's bar).
    """
    from egonet.caffe import RELEASES, checkpoint_from_caffemodel

    run = db.session.get(TrainingRun, run_id)
    if run is None:
        raise TrainingProblem(f"no training run with id {run_id}")
    try:
        if not claim_run(run, "reading the weights"):
            return run
        info = run.config["released"]
        reporter = _Reporter(run.id, on_progress)
        with holding_lease(run):
            state = checkpoint_from_caffemodel(path, size=(info["height"], info["width"]),
                                               releases=releases or RELEASES, progress=reporter, name=info["file"])
            relative = f"{files.run_folder(run.id)}/released.pt"
            reporter.say("writing the checkpoint", 0.95)
            files.save(relative, state)
        db.session.add(Checkpoint(run_id=run.id, fold="released", path=relative, epochs=0,
                                  metrics={"released": state["released"]}, test_frame_ids=[]))
        run.config = dict(run.config) | {"released": info | {"sha256": state["released"]["sha256"]}}
        done = db.session.execute(
            update(TrainingRun).where(TrainingRun.id == run.id, TrainingRun.status == RunStatus.RUNNING)
            .values(status=RunStatus.DONE, progress=1.0, finished_at=utcnow(), eta_s=None,
                    message=f"done: {state['released']['title']}, sha256 {state['released']['sha256'][:12]}")
        ).rowcount
        if not done:  # cancelled, or taken for dead, in its last moments: no checkpoint row
            raise Cancelled
        db.session.commit()
    except Cancelled:
        db.session.rollback()
    except Exception as exc:
        _failed(run_id, exc)
        if not isinstance(exc, EgonetError | TrainingProblem):
            raise
    db.session.refresh(run)
    return run


def _failed(run_id: int, exc: Exception) -> None:
    db.session.rollback()
    message = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    db.session.execute(
        update(TrainingRun).where(TrainingRun.id == run_id, TrainingRun.status.in_([RunStatus.QUEUED, RunStatus.RUNNING]))
        .values(status=RunStatus.FAILED, finished_at=utcnow(), eta_s=None, message=f"failed: {message}"[:2000])
    )
    db.session.commit()


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
        if status != RunStatus.RUNNING:  # cancelled, or failed once its worker was taken for dead
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
    pending = _remove_stale()
    if pending >= MAX_PENDING_UPLOADS:
        raise TrainingProblem(f"{MAX_PENDING_UPLOADS} uploads are under way already: finish or cancel one", status=409)
    token = secrets.token_hex(16)
    meta = {"filename": Path(filename).name, "size": size, "user_id": user.id, "created": time.time()}
    files.put(f"{UPLOADS}/{token}/{META}", json.dumps(meta).encode())
    return {"upload": token, "chunk_bytes": CHUNK_BYTES}


def write_chunk(token: str, *, offset: int, stream, length: int | None, user: User) -> int:
    """Store one chunk at ``offset`` (the bytes received so far); returns the new total.

    Each chunk is an object of its own in storage, so the chunks of one file
    may reach different web hosts. A chunk sent again after a lost answer
    (at an offset where a chunk began) replaces that chunk and drops those after it.

    Raises:
        TrainingProblem: 404 unknown upload; 411 no length; 413 a chunk over
            ``CHUNK_BYTES`` or past the size announced; 409 an offset ahead
            of the bytes received, or inside a chunk received (the answer says how many).
    """
    meta, parts = _upload(token, user)
    received = _received(parts)
    if length is None:
        raise TrainingProblem("send each chunk with a Content-Length", status=411)
    if length > CHUNK_BYTES or offset + length > meta["size"]:
        raise TrainingProblem(f"a chunk may hold {CHUNK_BYTES:,} bytes and end at {meta['size']:,} at most",
                              field="body", status=413)
    if offset > received or (offset < received and offset not in parts):
        raise TrainingProblem(f"offset {offset} is not where the next chunk of the {received} bytes received begins",
                              field="offset", status=409, received=received)

    def copy(fh) -> None:
        left = length
        while left:
            data = stream.read(min(left, 1 << 20))
            if not data:
                raise TrainingProblem(f"the chunk ended after {length - left} of {length} bytes", field="body")
            fh.write(data)
            left -= len(data)

    files.put(_part(token, offset), copy)
    for later in sorted(p for p in parts if p > offset):
        files.delete(_part(token, later))
    return offset + length


def finish_upload(token: str, *, name: str | None, size: tuple[int, int] | None, user: User) -> TrainingRun:
    """The whole file is here: check it is a release, record its run and queue the conversion.

    The chunks stay in storage until the worker (on whichever host) has converted them.

    Raises:
        TrainingProblem: 404 unknown upload; 409 bytes missing; 400 not a
            release (``file``; the upload is removed).
    """
    meta, parts = _upload(token, user)
    received = _received(parts)
    if received != meta["size"]:
        raise TrainingProblem(f"{received:,} of {meta['size']:,} bytes received: send the rest first", status=409,
                              received=received)
    files.delete(f"{UPLOADS}/{token}/{META}")  # no longer under way: neither counted as pending nor written to
    run = None
    try:
        with _assembled(token) as path:
            run = register_release(path, name=name, size=size, created_by=user, filename=meta["filename"])
    finally:
        if run is None:  # refused, or anything unforeseen: the upload goes
            files.delete_folder(f"{UPLOADS}/{token}")
    enqueue("import_weights", run.id, token)
    return run


def convert_upload(run_id: int, token: str) -> TrainingRun:
    """The worker's job for an upload: the chunks from storage into one file on this host, converted, then removed."""
    try:
        with _assembled(token) as path:
            return convert_release(run_id, path)
    except Exception as exc:  # the chunks could not be read (storage down): the run says so
        _failed(run_id, exc)
        raise
    finally:
        files.delete_folder(f"{UPLOADS}/{token}")


def cancel_upload(token: str, *, user: User) -> None:
    """Remove an unfinished upload."""
    _upload(token, user)
    files.delete_folder(f"{UPLOADS}/{token}")


def _upload(token: str, user: User) -> tuple[dict, dict[int, int]]:
    """The upload's announcement and its chunks (offset -> bytes)."""
    gone = TrainingProblem(f"no upload {token[:40]!r} under way (finished, cancelled or older than a day)", status=404)
    if not _TOKEN.fullmatch(token):
        raise gone
    try:
        meta = json.loads(files.read(f"{UPLOADS}/{token}/{META}"))
    except FileNotFoundError:
        raise gone from None
    if meta["user_id"] != user.id:
        raise TrainingProblem("this upload is another user's", status=404)
    parts = {}
    for path, size, _ in files.listing(f"{UPLOADS}/{token}"):
        if (name := path.rsplit("/", 1)[1]).startswith("part-"):
            parts[int(name.removeprefix("part-"))] = size
    return meta, parts


def _part(token: str, offset: int) -> str:
    return f"{UPLOADS}/{token}/part-{offset:015d}"


def _received(parts: dict[int, int]) -> int:
    """The bytes received from the start without a gap."""
    end = 0
    for offset in sorted(parts):
        if offset != end:
            break
        end += parts[offset]
    return end


@contextlib.contextmanager
def _assembled(token: str) -> Iterator[Path]:
    """The upload's chunks, in order, as one file in this host's cache (removed afterwards)."""
    folder = Path(current_app.config["CACHE_ROOT"]) / "uploads"
    folder.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=folder, suffix=".caffemodel")
    path = Path(name)
    try:
        with os.fdopen(fd, "wb") as fh:
            for part in sorted(p for p, _, _ in files.listing(f"{UPLOADS}/{token}") if p.rsplit("/", 1)[1].startswith("part-")):
                fh.write(files.read(part))  # one chunk (at most CHUNK_BYTES) at a time
        yield path
    finally:
        path.unlink(missing_ok=True)


def _remove_stale() -> int:
    """Remove unfinished uploads whose last chunk came more than a day ago; returns how many are left under way."""
    newest: dict[str, float] = {}
    pending = set()
    for path, _, modified in files.listing(UPLOADS):
        token = path.split("/")[1]
        newest[token] = max(newest.get(token, 0.0), modified)
        if path.endswith("/" + META):
            pending.add(token)
    for token in [t for t in pending if newest[t] < time.time() - STALE_UPLOAD_S]:
        files.delete_folder(f"{UPLOADS}/{token}")
        pending.discard(token)
    return len(pending)
