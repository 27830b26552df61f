"""A run started from the Training page is trained by a real worker process through the queue."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.extensions import db
from app.models import Activity
from app.models.training import RunStatus, TrainingRun
from app.services import training
from app.services.demo import create_demo

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_a_run_started_from_the_page_completes_through_the_worker(app, database_url, tmp_path, admin_client):
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, width=64, height=48)
        ids = list(db.session.execute(db.select(Activity.id).where(Activity.name.in_(["cooking", "dining"]))).scalars())
    form = {"model": "egonet-lite", "folds": "loao", "epochs": "1", "device": "cpu", "width": "32", "height": "24",
            "batch_size": "2", "seed": "0", "name": "queued from the page", "activities": [str(i) for i in ids]}
    assert admin_client.post("/training/runs", data=form).status_code == 302

    env = dict(
        os.environ,
        EGONET_QUEUE_URL=app.config["QUEUE_URL"],
        FLASK_SQLALCHEMY_DATABASE_URI=database_url,
        FLASK_SECRET_KEY="worker-test-secret-key-0123456789abcdef",  # no key file in the repository's instance/
        FLASK_STORAGE_URL=str(tmp_path),
        FLASK_CACHE_ROOT=str(tmp_path / "cache"),
        OMP_NUM_THREADS="1",
    )
    worker = subprocess.Popen(
        [sys.executable, "-m", "flask", "--app", "app", "egonet", "worker"],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        deadline = time.monotonic() + 120
        seen = set()
        while time.monotonic() < deadline:
            body = admin_client.get("/training/status").get_json()
            (run,) = body["runs"]
            seen.add(run["status"])
            if run["status"] in ("done", "failed", "cancelled"):
                break
            time.sleep(0.2)
    finally:
        worker.terminate()
        out = worker.communicate(timeout=20)[0]
    assert run["status"] == "done", out[-3000:]
    assert "running" in seen or "queued" in seen
    with app.app_context():
        done = db.session.get(TrainingRun, run["id"])
        assert done.status is RunStatus.DONE and [c.fold for c in done.checkpoints] == ["cooking", "dining"]
        assert len(list(training.held_out_predictions(done))) == 4
        assert (tmp_path / "checkpoints" / f"run-{done.id}" / "cooking.pt").exists()
    page = admin_client.get(f"/training/runs/{run['id']}")
    assert b"Held-out predictions" in page.data
