"""A page with queued work says when no worker is running: a real worker records a heartbeat on the real queue."""

import os
import subprocess
import sys
import time

import pytest

from app.queue import HEARTBEAT_KEY, current_huey, worker_last_seen
from tests.app.test_exchange import ROOT, labelled_dataset, recording


@pytest.mark.slow
def test_queued_work_says_no_worker_until_one_beats(app, database_url, admin_client, tmp_path):
    labelled_dataset(app, recording(tmp_path / "rec"))

    def queue_export() -> str:
        response = admin_client.post("/label/exports", data={"status": ["done", "reviewed"], "images": "1"})
        return response.location.rsplit("/", 1)[1]

    first = queue_export()
    page = admin_client.get(f"/label/exports/{first}").get_data(as_text=True)
    assert 'id="no-worker"' in page and "No worker has ever run on this queue" in page

    env = dict(os.environ, EGONET_QUEUE_URL=app.config["QUEUE_URL"], FLASK_SQLALCHEMY_DATABASE_URI=database_url,
               FLASK_SECRET_KEY="worker-test-secret-key-0123456789abcdef", FLASK_STORAGE_URL=str(tmp_path),
               FLASK_CACHE_ROOT=str(tmp_path / "cache"), OMP_NUM_THREADS="1")  # fmt: skip
    worker = subprocess.Popen([sys.executable, "-m", "flask", "--app", "app", "egonet", "worker"], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            state = admin_client.get(f"/api/label/exports/{first}").get_json()
            with app.app_context():
                seen = worker_last_seen()
            if state["status"] == "done" and seen is not None:
                break
            time.sleep(0.2)
    finally:
        worker.terminate()
        out = worker.communicate(timeout=20)[0]
    assert state["status"] == "done" and seen is not None and seen < 60, out[-3000:]

    # Queued again just after: the worker was seen lately, so no notice.
    second = queue_export()
    assert 'id="no-worker"' not in admin_client.get(f"/label/exports/{second}").get_data(as_text=True)
    # Its last heartbeat two minutes ago: the notice says so.
    with app.app_context():
        current_huey().put(HEARTBEAT_KEY, time.time() - 125)
    page = admin_client.get(f"/label/exports/{second}").get_data(as_text=True)
    assert "No worker has been seen for 2 min" in page


@pytest.mark.slow
def test_on_one_machine_the_app_runs_its_queue_itself(app_with, make_user, tmp_path):
    """The README's quick start (SQLite queue, QUEUE_IN_PROCESS on): an export
    with images finishes with no `flask egonet worker`, and no page says a worker is missing."""
    from app.queue import EXTENSION
    from tests.app.conftest import PASSWORD

    app = app_with(QUEUE_IN_PROCESS=True)
    assert app.config["QUEUE_URL"].startswith("sqlite:///")
    labelled_dataset(app, recording(tmp_path / "rec"))
    make_user("admin", "admin")
    client = app.test_client()
    assert client.login("admin", PASSWORD).status_code == 302  # the first request starts the consumer
    try:
        response = client.post("/label/exports", data={"status": ["done", "reviewed"], "images": "1"})
        export_id = response.location.rsplit("/", 1)[1]
        deadline = time.monotonic() + 60
        while (state := client.get(f"/api/label/exports/{export_id}").get_json())["status"] != "done":
            assert state["status"] in ("queued", "running") and time.monotonic() < deadline, state
            time.sleep(0.1)
        with client.get(f"/label/exports/{export_id}/download") as download:
            assert download.status_code == 200 and download.data[:2] == b"PK"
        # Queued work now: the consumer's heartbeat keeps the notice away.
        queued = client.post("/label/exports", data={"status": ["done", "reviewed"], "images": "1"}).location
        assert 'id="no-worker"' not in client.get(queued).get_data(as_text=True)
    finally:
        app.extensions[EXTENSION].stop_consumer()


def test_one_process_of_a_machine_consumes_and_another_takes_over(app_with, runner, monkeypatch):
    """Two app processes on one SQLite queue (gunicorn's workers): the lock elects one
    consumer; when it stops, the other takes over. Commands start no consumer."""
    from app import queue

    monkeypatch.setattr(queue, "HEARTBEAT_S", 0.1)  # how often a waiting process tries for the lock
    first, second = app_with(QUEUE_IN_PROCESS=True), app_with(QUEUE_IN_PROCESS=True)
    assert first.config["QUEUE_URL"] == second.config["QUEUE_URL"]
    one, other = first.extensions[queue.EXTENSION], second.extensions[queue.EXTENSION]
    try:
        assert first.test_cli_runner().invoke(args=["egonet", "classes", "list"]).exit_code == 0
        assert one._consumer is None  # a command is no server
        first.test_client().get("/login")
        assert one.consuming.wait(10)
        second.test_client().get("/login")
        assert other._consumer.is_alive() and not other.consuming.wait(0.5)  # standing by
        one.stop_consumer()
        assert not one.consuming.is_set() and other.consuming.wait(10)
    finally:
        one.stop_consumer()
        other.stop_consumer()
