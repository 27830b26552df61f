"""The authors' released weights in the app: import-weights, the page's upload, and using the release.

Fast tests use releases at 1/64 width (tests/caffe_files.py), passed to the
service; the command and the page accept only the authors' two releases, so
their end-to-end tests (slow) use a full-size RGB release file written once
a session (tests/conftest.py).
"""

import re
from pathlib import Path

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame
from app.models.training import FoldsMode, Prediction, RunStatus, TrainingRun
from app.services import training
from app.services.demo import create_demo
from app.services.labelling import proposers
from app.services.scoring import build_report
from app.services.training import released
from tests.caffe_files import TINY, TINY_RELEASES, release_layers, write_caffemodel, write_lying_blob


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


@pytest.fixture
def demo(app):
    """Two labelled demo frames per activity at 64x48 (with DHG)."""
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, width=64, height=48)


@pytest.fixture
def tiny_file(tmp_path):
    return write_caffemodel(tmp_path / "EgoNet_tiny.caffemodel", release_layers(TINY["rgb+dhg"], seed=5))


JSON = {"Accept": "application/json"}  # as the page's api.js asks


def frames() -> list[Frame]:
    return list(db.session.execute(db.select(Frame).order_by(Frame.id)).scalars())


def import_tiny(path, **options) -> TrainingRun:
    run = training.register_release(path, size=(48, 64), releases=TINY_RELEASES, **options)
    return training.convert_release(run.id, path, releases=TINY_RELEASES)


# --------------------------------------------------------------------------- the service


def test_a_release_becomes_a_run_with_one_checkpoint_that_predicts_scores_and_suggests(ctx, demo, tiny_file, admin_client):
    seen = []
    run = training.register_release(tiny_file, size=(48, 64), releases=TINY_RELEASES, name="authors")
    assert run.status is RunStatus.QUEUED and run.folds is FoldsMode.RELEASED and run.model_name == "egonet"
    run = training.convert_release(run.id, tiny_file, releases=TINY_RELEASES, on_progress=lambda d, t: seen.append(d / t))
    assert run.status is RunStatus.DONE and run.progress == 1.0 and seen[-1] == 1.0
    (checkpoint,) = run.checkpoints
    assert checkpoint.fold == "released" and checkpoint.test_frame_ids == []
    state = training.files.load(checkpoint.path)
    assert state["config"]["height"] == 48 and state["model"]["options"]["coords"] == "released"
    assert run.config["released"]["sha256"] == state["released"]["sha256"]
    assert tiny_file.exists()  # the CLI's file is the user's: never removed
    page = admin_client.get(f"/training/runs/{run.id}")
    assert page.status_code == 200 and b"authors" in page.data and b"released" in page.data

    # Not trained on our frames: every prediction is held out, and the scorer scores them all.
    made = training.predict(checkpoint, frames(), device="cpu")
    assert len(made) == 14 and all(p.held_out for p in made)
    report = build_report(run_ids=[run.id], baselines=False, study_ids=[])
    (row,) = report.rows
    assert row.name == f"released model, RGB+DHG (run {run.id})" and row.overall.n_frames == 14

    # Suggest takes it as a model that never saw the frame.
    frame = frames()[0]
    chosen, held_out, why = proposers.choose_checkpoint(run, frame)
    assert chosen.id == checkpoint.id and held_out and "released" in why


def test_a_file_that_is_no_release_is_refused_naming_the_layer(ctx, tiny_file):
    with pytest.raises(training.TrainingProblem) as info:
        training.register_release(tiny_file)  # the authors' releases only, by default
    assert info.value.field == "file"
    assert ("not the authors' RGB+DHG release: layer 'conv1_1' weights have shape (1, 3, 3, 3) in the file, "
            "(64, 3, 3, 3)") in info.value.message
    assert db.session.execute(db.select(TrainingRun)).first() is None


def test_a_released_run_cannot_be_trained_on(ctx, demo, tiny_file):
    run = import_tiny(tiny_file)
    with pytest.raises(training.TrainingProblem, match="no training state"):
        training.create_run(training.RunRequest(resume_from=run.checkpoints[0], epochs=3))
    run.status = RunStatus.FAILED
    db.session.commit()
    with pytest.raises(training.TrainingProblem, match="import the .caffemodel again") as info:
        training.resume_run(run)
    assert info.value.status == 409


def test_cancelling_a_conversion_stops_it(ctx, tiny_file, monkeypatch):
    run = training.register_release(tiny_file, size=(48, 64), releases=TINY_RELEASES)

    def cancel_then_go_on(done, total):
        db.session.execute(db.update(TrainingRun).values(status=RunStatus.CANCELLED))
        db.session.commit()

    run = training.convert_release(run.id, tiny_file, releases=TINY_RELEASES, on_progress=cancel_then_go_on)
    assert run.status is RunStatus.CANCELLED and run.checkpoints == []


# --------------------------------------------------------------------------- the page's upload


@pytest.mark.both_storages
def test_the_page_uploads_in_chunks_and_refuses_what_is_no_release(app, admin_client, tiny_file, monkeypatch):
    monkeypatch.setattr(released, "CHUNK_BYTES", 4096)
    data = tiny_file.read_bytes()
    page = admin_client.get("/training/")
    assert b"Import the authors' released weights" in page.data and b'id="weights-form"' in page.data

    start = admin_client.post("/training/weights/uploads", json={"filename": "EgoNet.caffemodel", "size": len(data)}, headers=JSON)
    assert start.status_code == 201 and start.json["chunk_bytes"] == 4096
    url = f"/training/weights/uploads/{start.json['upload']}"
    octets = {"content_type": "application/octet-stream", "headers": {"Accept": "application/json"}}
    ahead = admin_client.put(f"{url}?offset=4096", data=data[4096:8192], **octets)
    assert ahead.status_code == 409 and ahead.json["received"] == 0
    too_big = admin_client.put(f"{url}?offset=0", data=data[:8192], **octets)
    assert too_big.status_code == 413
    early = admin_client.post(f"{url}/finish", json={}, headers=JSON)
    assert early.status_code == 409 and "send the rest first" in early.json["message"]
    for offset in range(0, len(data), 4096):
        sent = admin_client.put(f"{url}?offset={offset}", data=data[offset:offset + 4096], **octets)
        assert sent.status_code == 200 and sent.json["received"] == min(len(data), offset + 4096)
    again = admin_client.put(f"{url}?offset=0", data=data[:4096], **octets)  # a chunk whose answer was lost
    assert again.status_code == 200 and again.json["received"] == 4096
    for offset in range(4096, len(data), 4096):
        admin_client.put(f"{url}?offset={offset}", data=data[offset:offset + 4096], **octets)
    finish = admin_client.post(f"{url}/finish", json={"name": "mine"}, headers=JSON)
    # The page accepts only the authors' releases: a small file of their layer names is refused, in one line.
    assert finish.status_code == 400 and finish.json["fields"] == {"file": finish.json["message"]}
    assert finish.json["message"].startswith(
        "EgoNet.caffemodel: not the authors' RGB+DHG release: layer 'conv1_1' weights have shape (1, 3, 3, 3) in the file")
    assert admin_client.post(f"{url}/finish", json={}, headers=JSON).status_code == 404  # the upload is gone
    with app.app_context():
        assert not training.files.listing(released.UPLOADS)


@pytest.mark.both_storages
def test_a_lying_file_is_refused_in_one_line_naming_it_as_uploaded_and_removed(app, admin_client, tmp_path):
    """Review: a blob shape of 2**63 gave a 500 and left the upload on disk; messages showed the instance's path."""
    for dims in ([2**63, 0], [2**63]):
        data = write_lying_blob(tmp_path / "lie.caffemodel", dims).read_bytes()
        start = admin_client.post("/training/weights/uploads", json={"filename": "lie.caffemodel", "size": len(data)}, headers=JSON)
        url = f"/training/weights/uploads/{start.json['upload']}"
        assert admin_client.put(f"{url}?offset=0", data=data, content_type="application/octet-stream", headers=JSON).status_code == 200
        finish = admin_client.post(f"{url}/finish", json={}, headers=JSON)
        assert finish.status_code == 400 and finish.json["message"].startswith("lie.caffemodel: "), finish.json
        assert app.instance_path not in finish.json["message"] and start.json["upload"] not in finish.json["message"]
        with app.app_context():
            assert not training.files.listing(released.UPLOADS)


@pytest.mark.both_storages
def test_upload_limits_and_cancelling(app, admin_client, client, make_user):
    app.config["WEIGHTS_MAX_BYTES"] = 1000
    too_big = admin_client.post("/training/weights/uploads", json={"filename": "a.caffemodel", "size": 1001}, headers=JSON)
    assert too_big.status_code == 413 and "WEIGHTS_MAX_BYTES" in too_big.json["message"]
    wrong = admin_client.post("/training/weights/uploads", json={"filename": "a.prototxt", "size": 10}, headers=JSON)
    assert wrong.status_code == 400 and wrong.json["fields"] == {"filename": wrong.json["message"]}
    tokens = [admin_client.post("/training/weights/uploads", json={"filename": "a.caffemodel", "size": 10}, headers=JSON).json["upload"]
              for _ in range(released.MAX_PENDING_UPLOADS)]
    assert admin_client.post("/training/weights/uploads", json={"filename": "a.caffemodel", "size": 10}, headers=JSON).status_code == 409
    assert admin_client.delete(f"/training/weights/uploads/{tokens[0]}").status_code == 204
    assert admin_client.post("/training/weights/uploads", json={"filename": "a.caffemodel", "size": 10}, headers=JSON).status_code == 201
    assert admin_client.put("/training/weights/uploads/not-a-token?offset=0", data=b"x").status_code == 404
    # Another admin cannot write into it.
    admin_client.post("/logout")
    make_user("admin", "other")
    client.login("other", "correct horse battery")
    assert client.put(f"/training/weights/uploads/{tokens[1]}?offset=0", data=b"x").status_code == 404


def test_annotators_cannot_upload(client, make_user):
    client.login_as(make_user("annotator"))
    assert client.post("/training/weights/uploads", json={"filename": "a.caffemodel", "size": 10}, headers=JSON).status_code == 403
    assert b"weights-form" not in client.get("/training/").data


# --------------------------------------------------------------------------- end to end, full size (slow)


def sqlite_only(app) -> None:
    """A 270 MB conversion is the same on either database; the fast tests above run on both."""
    if not app.config["SQLALCHEMY_DATABASE_URI"].startswith("sqlite"):
        pytest.skip("full-size conversions run once, on SQLite")


@pytest.mark.slow
@pytest.mark.one_database
def test_cli_import_weights_then_predict_and_score(app, demo, runner, full_rgb_caffemodel, tmp_path):
    sqlite_only(app)
    path, _ = full_rgb_caffemodel
    result = runner.invoke(args=["egonet", "import-weights", str(path), "--size", "64x48", "--name", "authors RGB"])
    assert result.exit_code == 0, result.output
    assert "Reading weights" in result.output and "the authors' RGB release, model egonet-rgb" in result.output
    checkpoint_id = int(re.search(r"checkpoint (\d+)", result.output).group(1))
    assert f"egonet predict {checkpoint_id}" in result.output
    result = runner.invoke(args=["egonet", "predict", str(checkpoint_id), "--activity", "cooking", "--device", "cpu"])
    assert result.exit_code == 0 and "2 predictions stored, 2 of held-out frames" in result.output, result.output
    with app.app_context():
        run = db.session.execute(db.select(TrainingRun)).scalar_one()
        assert run.name == "authors RGB" and run.created_by is None
        report = build_report(run_ids=[run.id], baselines=False, study_ids=[])
        assert report.rows[0].name.startswith("released model, RGB") and report.rows[0].overall.n_frames == 2
        maps = db.session.execute(db.select(Prediction)).scalars().all()
        assert all(np.isfinite(training.read_probability(p.path)).all() for p in maps)
    bad = tmp_path / "bad.caffemodel"
    bad.write_bytes(path.read_bytes()[:100_000])
    result = runner.invoke(args=["egonet", "import-weights", str(bad)])
    assert result.exit_code != 0 and "truncated" in result.output and "Traceback" not in result.output
