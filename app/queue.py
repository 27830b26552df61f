"""The task queue: long work (training, batch prediction) runs in a worker.

Huey, with SQLite storage in the instance folder by default (no server), or
Redis with ``QUEUE_URL=redis://host:6379/0`` (the setting defaults to the
``EGONET_QUEUE_URL`` environment variable). ``init_app`` gives each app its
queue from that setting, so the web app and ``flask egonet worker`` agree on
it; the Huey is made on first use, so an app that never queues a job creates
no file.

This module is a leaf: it knows the queue, not the jobs. The jobs are the
functions of ``app.tasks`` marked ``@job``; services queue one by name with
``enqueue("train_run", run_id)`` and return at once, and the worker runs it
inside an application context.

A running worker records a heartbeat in the queue's own storage every
``HEARTBEAT_S`` seconds (``worker_last_seen``), so a page with queued work
can say when no worker is running; with each beat (the first as it starts)
it also runs ``on_heartbeat`` of ``app.tasks``, the jobs' housekeeping
(runs whose worker died are queued again).

On one machine no second command is needed: with the default SQLite queue
(and ``QUEUE_IN_PROCESS``, on by default) the web app runs the consumer
itself, in a thread started by its first request (so ``flask db upgrade``
and the other commands start none, and neither does the Flask reloader's
watching parent). Of the processes serving the app (gunicorn's workers),
the one holding an exclusive lock on ``<queue file>.consumer.lock`` consumes;
the others try for the lock every ``HEARTBEAT_S``, so one takes over when
the holder exits. A Redis queue serves several machines: run
``flask egonet worker`` there.
"""

import fcntl
import logging
import threading
import time
from collections.abc import Callable
from functools import cached_property, update_wrapper, wraps
from importlib import import_module
from pathlib import Path
from urllib.parse import urlsplit

from flask import Flask, current_app
from huey import Huey, RedisHuey, SqliteHuey
from huey.api import Result, TaskWrapper

HEARTBEAT_KEY = "egonet:worker-heartbeat"
HEARTBEAT_S = 10.0
"""How often a running worker records that it is alive."""
WORKER_GONE_S = 60.0
"""A worker not seen for this long is taken as not running (pages with queued work say so)."""
POLL_S = 0.5
"""How often the in-process consumer looks for a job while the queue is empty."""
EXTENSION = "egonet.queue"
JOBS = "app.tasks"
"""The module whose ``@job`` functions the worker runs."""

_jobs: dict[str, "Job"] = {}
logger = logging.getLogger(__name__)


class Job:
    """A function the worker runs, made by ``@job``.

    Calling the job queues it on the current app's queue and returns Huey's
    ``Result`` at once; ``func`` is the function itself.
    """

    def __init__(self, func: Callable):
        update_wrapper(self, func)
        self.func = func
        self.name = func.__name__

    def __call__(self, *args) -> Result | None:
        return current_app.extensions[EXTENSION].task(self.name)(*args)


def job(func: Callable) -> Job:
    """Declare ``func`` a job of the queue (used in ``app.tasks``)."""
    _jobs[func.__name__] = Job(func)
    return _jobs[func.__name__]


def enqueue(name: str, *args) -> Result | None:
    """Queue job ``name`` of ``app.tasks`` with ``args`` for the worker; returns at once.

    The job is looked up on the module when called, so replacing it there
    (a test's ``monkeypatch``) replaces it for every caller.
    """
    return getattr(import_module(JOBS), name)(*args)


def make_huey(url: str) -> Huey:
    """A Huey instance for ``redis://...`` or ``sqlite:///path``."""
    if url.startswith(("redis://", "rediss://")):
        return RedisHuey("egonet", url=url)
    if not url.startswith("sqlite:///"):
        raise RuntimeError(f"QUEUE_URL (EGONET_QUEUE_URL) must start with redis:// or sqlite:///, got {url!r}")
    path = Path(urlsplit(url).path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return SqliteHuey("egonet", filename=str(path))


def _in_app_context(app: Flask, func: Callable) -> Callable:
    @wraps(func)  # keeps the job's module and name, which identify it in messages
    def run(*args):
        with app.app_context():
            return func(*args)

    return run


class AppQueue:
    """One app's queue (``app.extensions["egonet.queue"]``), made on first use."""

    def __init__(self, app: Flask, url: str):
        self.app = app
        self.url = url

    @cached_property
    def _registered(self) -> tuple[Huey, dict[str, TaskWrapper]]:
        huey = make_huey(self.url)
        import_module(JOBS)  # its @job decorators fill _jobs
        tasks = {name: huey.task(name=name)(_in_app_context(self.app, job.func)) for name, job in _jobs.items()}
        return huey, tasks

    @property
    def huey(self) -> Huey:
        return self._registered[0]

    def task(self, name: str) -> TaskWrapper:
        """Job ``name``, registered on this queue to run in this app's context."""
        return self._registered[1][name]

    _consumer: threading.Thread | None = None
    _stopping: threading.Event | None = None
    _starting = threading.Lock()

    @cached_property
    def consuming(self) -> threading.Event:
        """Set while this process's in-process consumer holds the machine's lock and runs jobs."""
        return threading.Event()

    def start_consumer(self) -> None:
        """Run this app's jobs in a thread of this process, once (the first request calls it)."""
        if self._consumer is not None:
            return
        with self._starting:
            if self._consumer is None:
                self._stopping = threading.Event()
                self._consumer = threading.Thread(target=self._consume, args=(self._stopping,),
                                                  name="egonet-queue-consumer", daemon=True)
                self._consumer.start()

    def stop_consumer(self, timeout: float = 30.0) -> None:
        """Stop the in-process consumer after the job it is running (tests, shutdown)."""
        if self._consumer is not None:
            self._stopping.set()
            self._consumer.join(timeout)
            self._consumer = None

    def _consume(self, stopping: threading.Event) -> None:
        lock_path = Path(urlsplit(self.url).path + ".consumer.lock")
        lock_path.parent.mkdir(parents=True, exist_ok=True)
        with open(lock_path, "a+b") as lock:
            while True:  # another process may hold the lock: stand by until it lets go
                try:
                    fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if stopping.wait(HEARTBEAT_S):
                        return
            self.consuming.set()
            try:
                beating = threading.Thread(target=_beat, args=(self.app, self.huey, stopping),
                                           name="egonet-queue-heartbeat", daemon=True)
                beating.start()
                while not stopping.is_set():
                    try:
                        task = self.huey.dequeue()
                        if task is None:
                            stopping.wait(POLL_S)
                        else:
                            self.huey.execute(task)  # Huey logs and records a job's own failure
                    except Exception:  # the queue's file unreadable for a moment: try again
                        logger.exception("in-process queue consumer")
                        stopping.wait(HEARTBEAT_S)
            finally:
                self.consuming.clear()
                fcntl.flock(lock, fcntl.LOCK_UN)


def init_app(app: Flask) -> None:
    queue = app.extensions[EXTENSION] = AppQueue(app, app.config["QUEUE_URL"])
    if app.config["QUEUE_IN_PROCESS"] and queue.url.startswith("sqlite:///"):
        app.before_request(queue.start_consumer)


def current_huey() -> Huey:
    """The current app's Huey."""
    return current_app.extensions[EXTENSION].huey


def worker_last_seen() -> float | None:
    """Seconds since a worker last recorded its heartbeat on the current app's queue; None if none ever did."""
    beat = current_huey().get(HEARTBEAT_KEY, peek=True)
    return None if beat is None else max(0.0, time.time() - float(beat))


def worker_running() -> bool:
    """Whether a worker was seen within ``WORKER_GONE_S``."""
    seen = worker_last_seen()
    return seen is not None and seen < WORKER_GONE_S


def _beat(app: Flask, huey: Huey, stop: threading.Event) -> None:
    """Record that a consumer of ``huey`` is alive, and do the jobs' housekeeping, now and every ``HEARTBEAT_S``
    until ``stop``."""
    while True:
        try:
            huey.put(HEARTBEAT_KEY, time.time())
            with app.app_context():
                import_module(JOBS).on_heartbeat()
        except Exception:  # the queue or the database away for a moment: the next beat tries again
            logger.exception("worker heartbeat")
        if stop.wait(HEARTBEAT_S):
            return


def run_worker(*, workers: int = 1) -> None:
    """Consume the current app's jobs until interrupted (``flask egonet worker``), beating every ``HEARTBEAT_S``."""
    huey = current_huey()
    stop = threading.Event()
    beating = threading.Thread(target=_beat, args=(current_app._get_current_object(), huey, stop),
                               name="egonet-worker-heartbeat", daemon=True)
    beating.start()
    # Threads share the process; the training jobs themselves use torch's threads.
    consumer = huey.create_consumer(workers=workers, worker_type="thread", periodic=False)
    try:
        consumer.run()
    finally:
        stop.set()
