"""Checkpoints in storage, on a folder and on a bucket: a run trained on one host is used, resumed and
downloaded on another (the same database and STORAGE_URL, an instance and cache of its own)."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from datetime import timedelta
from pathlib import Path

import pytest
from sqlalchemy import update

from app.extensions import db
from app.models import Activity, Frame, utcnow
from app.models.training import Checkpoint, RunStatus, TrainingRun
from app.services import training
from app.services.demo import create_demo
from app.services.training import released
from tests.app.conftest import PASSWORD, make_app
from tests.caffe_files import TINY, TINY_RELEASES, release_layers, write_caffemodel

pytestmark = [pytest.mark.both_storages, pytest.mark.usefixtures("one_thread")]

ROOT = Path(__file__).resolve().parents[2]
RUN = {"model": "egonet-lite", "epochs": 1, "width": 32, "height": 24, "batch_size": 2, "device": "cpu"}
JSON = {"Accept": "application/json"}


@pytest.fixture
def demo(app):
    """Two labelled demo frames of cooking and dining at 64x48; returns their activity ids."""
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, width=64, height=48)
        return tuple(db.session.execute(
            db.select(Activity.id).where(Activity.name.in_(["cooking", "dining"])).order_by(Activity.name)).scalars())


@pytest.fixture
def other_host(app_with, storage_url, tmp_path):
    """A second host: its own instance folder and cache, the same database and storage."""
    return app_with(STORAGE_URL=storage_url, CACHE_ROOT=str(tmp_path / "host-b" / "cache"))


def names(run_id: int) -> set[str]:
    return {path.rsplit("/", 1)[1] for path, _, _ in training.files.listing(f"run-{run_id}")}


def test_checkpoint_root_is_refused_at_startup(database_url, tmp_path):
    with pytest.raises(RuntimeError, match="CHECKPOINT_ROOT is replaced by STORAGE_URL"):
        make_app(database_url, tmp_path, CHECKPOINT_ROOT=str(tmp_path / "checkpoints"))


def test_a_run_trains_into_storage_and_another_host_predicts_and_downloads_it(app, demo, other_host, storage_url, tmp_path,
                                                                               make_user):
    with app.app_context():
        run = training.execute_run(training.create_run(training.RunRequest(**RUN, activity_ids=demo)).id)
        assert run.status is RunStatus.DONE and names(run.id) == {"config.json", "cooking.pt", "dining.pt"}
        cooking = next(c for c in run.checkpoints if c.fold == "cooking")
        stored = training.files.read(cooking.path)
        assert not (Path(app.config["CACHE_ROOT"]) / "training" / f"run-{run.id}").exists()  # the scratch folder went
    if storage_url.startswith("s3://"):
        assert not (tmp_path / "checkpoints").exists()  # nothing of the run on this host's disk but its cache
    make_user("admin", "admin")
    client = other_host.test_client()
    assert client.login("admin", PASSWORD).status_code == 302
    with client.get(f"/training/checkpoints/{cooking.id}/download") as response:
        assert response.status_code == 200 and response.data == stored
    assert client.get(f"/training/runs/{run.id}/config.json").get_json()["engine"]["config"]["width"] == 32
    with other_host.app_context():
        frames = list(db.session.execute(db.select(Frame).order_by(Frame.id)).scalars())
        made = training.predict(db.session.get(Checkpoint, cooking.id), frames, device="cpu")
        assert len(made) == len(frames) > 4
    # Deleting the run (from the second host) deletes its files in storage.
    assert client.post(f"/training/runs/{run.id}/delete").status_code == 302
    with app.app_context():
        assert names(run.id) == set()


def test_a_run_stopped_after_an_epoch_resumes_on_another_host_from_storage(app, demo, other_host, monkeypatch):
    def killed_in_second_epoch(progress):
        if progress.phase == "train" and progress.epoch == 2:
            raise KeyboardInterrupt  # as when the worker's host goes away: nothing after epoch 1 reaches storage

    with app.app_context():
        run_id = training.create_run(training.RunRequest(**(RUN | {"epochs": 2}), activity_ids=demo)).id
        with pytest.raises(KeyboardInterrupt):
            training.execute_run(run_id, on_progress=killed_in_second_epoch)
        assert training.files.load(f"run-{run_id}/cooking.pt")["epoch"] == 1 and names(run_id) == {"config.json", "cooking.pt"}
        monkeypatch.setattr("app.tasks.train_run", lambda run_id: None)
        training.resume_run(db.session.get(TrainingRun, run_id))

    seen = []
    with other_host.app_context():
        run = training.execute_run(run_id, on_progress=lambda p: seen.append((p.fold, p.epoch, p.phase)))
        assert run.status is RunStatus.DONE and [c.fold for c in run.checkpoints] == ["cooking", "dining"]
        # The cooking fold went on at epoch 2; dining, never started, trained both epochs.
        assert {e for f, e, phase in seen if f == "cooking" and phase == "train"} == {0, 2}
        assert {e for f, e, phase in seen if f == "dining" and phase == "train"} == {0, 1, 2}
        cooking = next(c for c in run.checkpoints if c.fold == "cooking")
        assert [h["epoch"] for h in training.files.load(cooking.path)["history"]] == [1, 2]


def test_a_run_whose_worker_stopped_renewing_its_lease_is_taken_over_by_another_host(app, demo, other_host, monkeypatch):
    queued = []
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: queued.append(run_id))

    def lease_runs_out_in_second_epoch(progress):
        if progress.phase == "train" and progress.epoch == 2 and not queued:
            with other_host.app_context():  # this worker froze past its lease; the other host's heartbeat sees it
                db.session.execute(update(TrainingRun).where(TrainingRun.id == run_id)
                                   .values(updated_at=utcnow() - timedelta(seconds=app.config["TRAINING_LEASE_S"] + 1)))
                db.session.commit()
                assert training.take_over_stopped_runs() == [run_id]

    with app.app_context():
        run_id = training.create_run(training.RunRequest(**(RUN | {"epochs": 2}), activity_ids=demo)).id
        run = training.execute_run(run_id, on_progress=lease_runs_out_in_second_epoch)
        # The frozen attempt stopped at its next report and left the run to the taker, queued once.
        assert run.status is RunStatus.QUEUED and queued == [run_id] and run.checkpoints == []
        assert run.message.startswith("resumed after its worker stopped at ") and names(run_id) == {"config.json", "cooking.pt"}

    seen = []
    with other_host.app_context():
        run = training.execute_run(run_id, on_progress=lambda p: seen.append((p.fold, p.epoch, p.phase)))
        assert run.status is RunStatus.DONE and [c.fold for c in run.checkpoints] == ["cooking", "dining"]
        assert {e for f, e, phase in seen if f == "cooking" and phase == "train"} == {0, 2}


def test_a_released_model_uploaded_through_two_hosts_is_converted_by_a_third(app, app_with, storage_url, tmp_path,
                                                                            other_host, make_user, monkeypatch):
    from app.tasks import import_weights

    monkeypatch.setattr("egonet.caffe.RELEASES", TINY_RELEASES)
    monkeypatch.setattr(released, "CHUNK_BYTES", 4096)
    queued = []
    monkeypatch.setattr("app.tasks.import_weights", lambda *args: queued.append(args))
    data = write_caffemodel(tmp_path / "EgoNet.caffemodel", release_layers(TINY["rgb+dhg"], seed=5)).read_bytes()
    make_user("admin", "admin")
    clients = [app.test_client(), other_host.test_client()]
    for client in clients:
        assert client.login("admin", PASSWORD).status_code == 302
    start = clients[0].post("/training/weights/uploads", json={"filename": "EgoNet.caffemodel", "size": len(data)}, headers=JSON)
    url = f"/training/weights/uploads/{start.json['upload']}"
    octets = {"content_type": "application/octet-stream", "headers": JSON}
    for i, offset in enumerate(range(0, len(data), 4096)):  # the load balancer alternates
        sent = clients[i % 2].put(f"{url}?offset={offset}", data=data[offset:offset + 4096], **octets)
        assert sent.status_code == 200 and sent.json["received"] == min(len(data), offset + 4096)
    assert i >= 2
    finish = clients[1].post(f"{url}/finish", json={"name": "authors", "width": 64, "height": 48}, headers=JSON)
    assert finish.status_code in (200, 201), finish.json
    ((run_id, upload),) = queued

    worker = app_with(STORAGE_URL=storage_url, CACHE_ROOT=str(tmp_path / "host-c" / "cache"))
    with worker.app_context():
        import_weights.func(run_id, upload)
        run = db.session.get(TrainingRun, run_id)
        assert run.status is RunStatus.DONE, run.message
        (checkpoint,) = run.checkpoints
        assert training.files.load(checkpoint.path)["config"]["height"] == 48
        assert training.files.listing(released.UPLOADS) == []  # the chunks are gone once converted


@pytest.mark.slow
def test_torchrun_trains_on_two_processes_on_a_host_of_its_own_and_rank_zero_writes_to_storage(
        app, demo, database_url, storage_url, tmp_path):
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    env = dict(os.environ, FLASK_SQLALCHEMY_DATABASE_URI=database_url, FLASK_SECRET_KEY="torchrun-test-secret-key-0123456789",
               FLASK_STORAGE_URL=storage_url, FLASK_CACHE_ROOT=str(tmp_path / "gpu-host" / "cache"), OMP_NUM_THREADS="1")
    args = ["--folds", "loao", "--epochs", "2", "--size", "32x24", "--batch-size", "4", "--device", "cpu",
            "--activities", "cooking", "--activities", "dining", "--name", "two processes"]
    done = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--nproc-per-node", "2", "--master-port", str(port),
                           "-m", "flask", "--app", "app", "egonet", "train", *args],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    with app.app_context():
        run = db.session.execute(db.select(TrainingRun).filter_by(name="two processes")).scalar_one()
        assert run.status is RunStatus.DONE and names(run.id) == {"config.json", "cooking.pt", "dining.pt"}
        assert json.loads(training.files.read(f"run-{run.id}/config.json"))["environment"]["world_size"] == 2
        assert all(training.files.load(c.path)["epoch"] == 2 for c in run.checkpoints)
    assert not list((tmp_path / "gpu-host" / "cache" / "training").iterdir())  # both processes' scratch folders went


def test_an_upload_left_unfinished_for_a_day_is_removed(app, admin_client, monkeypatch):
    def start():
        return admin_client.post("/training/weights/uploads", json={"filename": "a.caffemodel", "size": 10}, headers=JSON).json["upload"]

    first = start()
    chunk = {"data": b"01234", "content_type": "application/octet-stream", "headers": JSON}
    assert admin_client.put(f"/training/weights/uploads/{first}?offset=0", **chunk).json["received"] == 5
    monkeypatch.setattr(released, "STALE_UPLOAD_S", -60)  # a day has passed
    second = start()
    assert admin_client.put(f"/training/weights/uploads/{first}?offset=5", **chunk).status_code == 404
    with app.app_context():
        assert {path.split("/")[1] for path, _, _ in training.files.listing(released.UPLOADS)} == {second}


def worker(app, database_url: str, storage_url: str, host: Path) -> subprocess.Popen:
    """``flask egonet worker`` on a host of its own: the same database, queue and storage, its own (empty)
    instance folder and cache; a lease of 4 s."""
    (host / "instance").mkdir(parents=True)
    env = dict(os.environ, EGONET_QUEUE_URL=app.config["QUEUE_URL"], FLASK_SQLALCHEMY_DATABASE_URI=database_url,
               FLASK_SECRET_KEY="worker-test-secret-key-0123456789abcdef", FLASK_STORAGE_URL=storage_url,
               FLASK_CACHE_ROOT=str(host / "cache"), FLASK_TRAINING_LEASE_S="4", OMP_NUM_THREADS="1")
    factory = f"app:create_app(instance_path={str(host / 'instance')!r})"
    return subprocess.Popen([sys.executable, "-m", "flask", "--app", factory, "egonet", "worker"], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)


@pytest.mark.slow
def test_a_worker_killed_mid_training_is_taken_over_by_a_worker_on_another_host_from_the_last_checkpoint_in_storage(
        app, demo, database_url, storage_url, tmp_path):
    epochs = 6
    with app.app_context():
        run_id = training.start_run(training.RunRequest(**(RUN | {"epochs": epochs}), activity_ids=demo)).id
    first = worker(app, database_url, storage_url, tmp_path / "host-a")
    try:
        deadline = time.monotonic() + 120
        with app.app_context():
            while not training.files.exists(f"run-{run_id}/cooking.pt") and time.monotonic() < deadline:
                time.sleep(0.05)
    finally:
        os.killpg(first.pid, signal.SIGKILL)  # the host goes away mid-training
        first.communicate(timeout=20)
    with app.app_context():
        state = training.files.load(f"run-{run_id}/cooking.pt")
        assert 1 <= state["epoch"] < epochs
        # Mark the stored checkpoint: only a run that goes on from it keeps the mark in its history.
        state["history"][0]["train_loss"] = 123.0
        training.files.save(f"run-{run_id}/cooking.pt", state)
        assert db.session.get(TrainingRun, run_id).status is RunStatus.RUNNING  # as the killed worker left it

    # No cancel, no resume: the second worker takes the run over once its lease has expired.
    second = worker(app, database_url, storage_url, tmp_path / "host-b")
    try:
        deadline = time.monotonic() + 180
        with app.app_context():
            while time.monotonic() < deadline:
                db.session.expire_all()
                if db.session.get(TrainingRun, run_id).status in (RunStatus.DONE, RunStatus.FAILED):
                    break
                time.sleep(0.2)
    finally:
        os.killpg(second.pid, signal.SIGTERM)
        out = second.communicate(timeout=20)[0]
    with app.app_context():
        run = db.session.get(TrainingRun, run_id)
        assert run.status is RunStatus.DONE, out[-3000:]
        assert run.config["worker_stopped"] and f"run {run_id}: its worker stopped at" in out
        cooking = next(c for c in run.checkpoints if c.fold == "cooking")
        history = training.files.load(cooking.path)["history"]
        assert [h["epoch"] for h in history] == list(range(1, epochs + 1)) and history[0]["train_loss"] == 123.0
