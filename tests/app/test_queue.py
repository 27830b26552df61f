"""Jobs go through a real queue and come back from a real worker process."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.queue import current_huey, enqueue, make_huey
from app.tasks import ping

ROOT = Path(__file__).resolve().parents[2]


def start_worker(database_url: str, tmp_path, queue_url: str) -> subprocess.Popen:
    env = dict(
        os.environ,
        EGONET_QUEUE_URL=queue_url,
        FLASK_SQLALCHEMY_DATABASE_URI=database_url,
        FLASK_SECRET_KEY="worker-test-secret-key-0123456789abcdef",  # no key file in the repository's instance/
        FLASK_STORAGE_URL=str(tmp_path),
    )
    return subprocess.Popen(
        [sys.executable, "-m", "flask", "--app", "app", "egonet", "worker"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def wait_result(result, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = result.get()
        if value is not None:
            return value
        time.sleep(0.1)
    raise TimeoutError("the worker did not answer")


@pytest.mark.slow
def test_sqlite_queue_round_trip_through_the_worker(app, database_url, tmp_path):
    worker = start_worker(database_url, tmp_path, app.config["QUEUE_URL"])
    try:
        with app.app_context():
            result = enqueue("ping", 41)
        assert wait_result(result) == 42
    finally:
        worker.terminate()
        out = worker.communicate(timeout=10)[0]
    assert "SqliteStorage queue" in out


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("EGONET_TEST_REDIS_URL"), reason="EGONET_TEST_REDIS_URL not set")
def test_redis_queue_round_trip_through_the_worker(database_url, tmp_path):
    url = os.environ["EGONET_TEST_REDIS_URL"]
    redis_huey = make_huey(url)
    redis_huey.flush()
    task = redis_huey.task(name=ping.name)(ping.func)  # the same job, enqueued on Redis
    worker = start_worker(database_url, tmp_path, url)
    try:
        assert wait_result(task(1)) == 2
    finally:
        worker.terminate()
        out = worker.communicate(timeout=10)[0]
        redis_huey.flush()
    assert "RedisStorage queue" in out


def test_queue_url_is_checked(ctx):
    huey = current_huey()
    with pytest.raises(RuntimeError, match="EGONET_QUEUE_URL"):
        make_huey("mysql://nope")
    assert type(huey.storage).__name__ == "SqliteStorage"
