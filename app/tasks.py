"""The task queue: long work (training, batch prediction) runs in a worker.

Huey with SQLite storage in the instance folder is the embedded default (no
server needed); set ``EGONET_QUEUE_URL=redis://host:6379/0`` to use Redis.
The URL is read from the environment when this module is imported, so the
web app and ``flask egonet worker`` agree on it without sharing an app
object. Views enqueue jobs and return at once; the worker runs them inside
an application context of its own.
"""

import os
from pathlib import Path
from urllib.parse import urlsplit

from flask import Flask
from huey import Huey, RedisHuey, SqliteHuey

DEFAULT_QUEUE = Path(__file__).resolve().parent.parent / "instance" / "queue.sqlite3"


def make_huey(url: str | None) -> Huey:
    """A Huey instance for ``redis://...`` or ``sqlite:///path`` (default: the instance folder)."""
    if url and url.startswith(("redis://", "rediss://")):
        return RedisHuey("egonet", url=url)
    path = Path(urlsplit(url).path) if url else DEFAULT_QUEUE
    if url and not url.startswith("sqlite:///"):
        raise RuntimeError(f"EGONET_QUEUE_URL must start with redis:// or sqlite:///, got {url!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    return SqliteHuey("egonet", filename=str(path))


huey = make_huey(os.environ.get("EGONET_QUEUE_URL"))

# The Flask app the worker runs tasks in; set by ``run_worker``.
_app: Flask | None = None


def app_context():
    if _app is None:
        raise RuntimeError("tasks run in `flask egonet worker`, which sets the app")
    return _app.app_context()


def run_worker(app: Flask, *, workers: int = 1) -> None:
    """Consume jobs until interrupted (``flask egonet worker``)."""
    global _app
    _app = app
    # Threads share the process; the training jobs themselves use torch's threads.
    consumer = huey.create_consumer(workers=workers, worker_type="thread", periodic=False)
    consumer.run()


@huey.task()
def ping(value: int) -> int:
    """A job that only proves the queue round trip (used by tests and `flask egonet worker --check`)."""
    with app_context():
        return value + 1


@huey.task()
def train_run(run_id: int) -> None:
    """Train a queued run (see app.services.training.execute_run)."""
    with app_context():
        from app.services.training import execute_run

        execute_run(run_id)


@huey.task()
def predict_frames(checkpoint_id: int, frame_ids: list[int], device: str = "auto") -> int:
    """Run a checkpoint on frames and store the predictions; returns how many."""
    with app_context():
        from app.extensions import db
        from app.models.training import Checkpoint
        from app.services.training import TrainingProblem, frames_for_prediction, predict

        checkpoint = db.session.get(Checkpoint, checkpoint_id)
        if checkpoint is None:
            raise TrainingProblem(f"no checkpoint with id {checkpoint_id}")
        return len(predict(checkpoint, frames_for_prediction(frame_ids=frame_ids), device=device))
