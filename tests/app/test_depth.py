"""Depth for RGB-only frames: `train-depth` as a training run, `predict-depth`, `import --depth-source predicted`,
and the mark wherever depth is shown or used (frame page, label page, export, score reports)."""

import json
import re

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame, Status
from app.models.training import RunStatus, TrainingEpoch, TrainingRun
from app.services import media, training
from app.services.demo import create_demo
from app.services.exchange import ExportOptions
from app.services.exchange.writing import export_folder
from app.services.importing import import_path
from app.services.scoring import methods
from app.services.scoring.provenance import Provenance
from app.services.training.depth import DepthRequest, create_depth_run, measured_depth_frames, predict_depth
from egonet import io
from egonet.depth import DEPTH_MODEL, assumed_intrinsics
from egonet.dhg import decode_dhg
from tests.app.factories import image_folder

pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py

TINY = ["--epochs", "2", "--size", "32x24", "--batch-size", "4", "--device", "cpu"]


@pytest.fixture
def demo(app):
    """Two demo frames of each activity at 64x48 (RGB-D with intrinsics)."""
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, width=64, height=48)


def newest_run() -> TrainingRun:
    return db.session.execute(db.select(TrainingRun).order_by(TrainingRun.id.desc())).scalars().first()


def rgb_only(tmp_path, n=2):
    """An activity "gaze" of RGB frames without depth or intrinsics."""
    import_path(image_folder(tmp_path / "gaze", n=n), activity="gaze")
    return db.session.execute(db.select(Frame).join(Frame.sequence).where(Frame.depth_path.is_(None))).scalars().all()


@pytest.mark.slow
def test_train_depth_is_a_training_run_with_its_epochs_left_out_of_scoring(app, demo, runner):
    result = runner.invoke(args=["egonet", "train-depth", *TINY, "--name", "depth run"])
    assert result.exit_code == 0, result.output
    assert re.search(r"run \d+ \(depth run\): done", result.output)
    assert re.search(r"held-out \(7 frames\): AbsRel \d+\.\d{3} delta<1\.25 \d\.\d{3}; median-scaled", result.output)
    assert re.search(r"constant \d\.\d\d m: \d+\.\d{3} / \d\.\d{3}", result.output)
    with app.app_context():
        run = newest_run()
        assert run.status is RunStatus.DONE and run.model_name == DEPTH_MODEL and run.config["frames"] == 14
        (checkpoint,) = run.checkpoints
        assert checkpoint.fold == "depth" and len(checkpoint.test_frame_ids) == 7  # the last of each activity's two
        epochs = db.session.execute(db.select(TrainingEpoch).filter_by(run_id=run.id).order_by(TrainingEpoch.epoch)).scalars().all()
        assert [(e.fold, e.epoch) for e in epochs] == [("depth", 1), ("depth", 2)]
        assert all(e.train_loss is not None and e.loss is not None and e.max_f is None for e in epochs)
        assert [h["epoch"] for h in checkpoint.metrics["history"]] == [1, 2]
        assert 0 <= run.metrics["depth"]["delta1"] <= 1
        # Not an action-object model: not scored, not offered to Suggest, refused by `predict`.
        assert run not in training.completed_runs()
        from app.services.labelling.proposers import SuggestProblem, resolve_run, suggestion_runs

        assert run not in suggestion_runs()
        with pytest.raises(SuggestProblem, match="predicts depth"):
            resolve_run(run.id)
        checkpoint_id = checkpoint.id
    result = runner.invoke(args=["egonet", "predict", str(checkpoint_id), "--device", "cpu"])
    assert result.exit_code == 1 and "predict-depth" in result.output


def test_train_depth_refuses_too_little_data_and_bad_options(app, runner):
    with app.app_context():
        with pytest.raises(training.TrainingProblem, match="at least two frames with measured depth") as info:
            create_depth_run(DepthRequest(epochs=1))
        assert info.value.field == "activities"
    result = runner.invoke(args=["egonet", "train-depth", "--size", "8x8"])
    assert result.exit_code == 1 and "width must be an integer in 16..4096" in result.output


def test_predict_depth_fills_frames_without_depth_marked_predicted_and_keeps_measured_depth(app, demo, runner, tmp_path,
                                                                                           admin_client):
    assert runner.invoke(args=["egonet", "train-depth", *TINY]).exit_code == 0
    with app.app_context():
        run_id = newest_run().id
    page = admin_client.get(f"/training/runs/{run_id}").get_data(as_text=True)
    assert 'id="depth-errors"' in page and 'data-loss-label="scale-invariant loss"' in page
    assert 'id="chart-mf"' not in page and "frames with measured depth" in page
    with app.app_context():
        (frame, other) = rgb_only(tmp_path)
        measured = {f.id: (f.depth_path, f.dhg_path) for f in measured_depth_frames()}
        report = predict_depth("gaze", device="cpu")
        assert (report.predicted, report.assumed_intrinsics, report.kept_measured) == (2, 2, 0)
        db.session.refresh(frame)
        assert frame.depth_predicted and frame.meta["intrinsics_assumed"] is True
        assert frame.meta["depth_model"] == f"{DEPTH_MODEL} run {newest_run().id} checkpoint {report.checkpoint_id}"
        assert frame.meta["assumed_intrinsics"]["fx"] == pytest.approx(assumed_intrinsics(64, 48)[0, 0], abs=0.005)
        assert frame.fx is None  # the frame's own camera stays unknown
        depth = io.read_depth(media.local_path(frame.depth_path))
        assert depth.shape == (48, 64) and (depth >= 0.1).all() and (depth <= 10).all()
        decoded = decode_dhg(io.read_dhg(media.local_path(frame.dhg_path)))
        assert np.allclose(decoded.depth, depth, atol=10 / 255 + 1e-3)  # the DHG is made from that depth
        # An activity with measured depth: nothing replaced.
        cooking = predict_depth("cooking", device="cpu")
        assert (cooking.predicted, cooking.kept_measured) == (0, 2)
        assert {f.id: (f.depth_path, f.dhg_path) for f in measured_depth_frames()} == measured
        # Predicted frames never train a depth network.
        assert frame.id not in {f.id for f in measured_depth_frames()}
    result = runner.invoke(args=["egonet", "predict-depth", "--activity", "gaze", "--device", "cpu"])
    assert result.exit_code == 0 and "2 frames given predicted depth and DHG (2 with assumed intrinsics)" in result.output
    result = runner.invoke(args=["egonet", "predict-depth", "--activity", "nowhere"])
    assert result.exit_code == 1 and "no activity named 'nowhere'" in result.output


def test_predict_depth_without_a_depth_run_says_what_to_do(ctx, tmp_path):
    rgb_only(tmp_path, n=1)
    with pytest.raises(training.TrainingProblem, match="flask egonet train-depth"):
        predict_depth("gaze")


def test_import_depth_source_predicted_marks_frames_and_assumes_intrinsics(app, runner, tmp_path):
    folder = image_folder(tmp_path / "est", n=2, depth=True)
    result = runner.invoke(args=["egonet", "import", str(folder), "--activity", "gaze", "--depth-source", "predicted"])
    assert result.exit_code == 0, result.output
    measured = image_folder(tmp_path / "rgbd", n=1, depth=True, intrinsics=True)
    assert runner.invoke(args=["egonet", "import", str(measured), "--activity", "room"]).exit_code == 0
    with app.app_context():
        frames = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().all()
        assert [f.depth_predicted for f in frames] == [True, True, False]
        assert frames[0].dhg_path is not None and frames[0].meta["intrinsics_assumed"] is True
        assert "intrinsics_assumed" not in frames[2].meta
    result = runner.invoke(args=["egonet", "import", str(folder), "--activity", "gaze", "--depth-source", "guessed"])
    assert result.exit_code == 2 and "--depth-source" in result.output


def test_the_mark_shows_on_the_frame_and_label_pages_and_in_exports(app, admin_client, tmp_path):
    with app.app_context():
        import_path(image_folder(tmp_path / "est", n=1, depth=True, masks=True), activity="gaze", depth_source="predicted")
        import_path(image_folder(tmp_path / "rgbd", n=1, depth=True, intrinsics=True, masks=True), activity="room")
        predicted, measured = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().all()
        export_folder(tmp_path / "out", ExportOptions.of(fmt="coco", statuses=[Status.DONE]))
    page = admin_client.get(f"/frames/{predicted.id}").get_data(as_text=True)
    assert 'class="depth-predicted"' in page and "from predicted depth" in page and "intrinsics assumed (60° wide)" in page
    assert '<td id="depth-source">predicted from the RGB</td>' in page and "its DHG assumed a 60° wide camera (fx " in page
    assert "assumed_intrinsics" not in page and "hfov_deg" not in page  # in words, not the stored record
    other = admin_client.get(f"/frames/{measured.id}").get_data(as_text=True)
    assert "depth-predicted" not in other and '<td id="depth-source">measured</td>' in other
    label = admin_client.get(f"/label/frames/{predicted.id}").get_data(as_text=True)
    assert "Depth predicted" in label
    coco = json.loads((tmp_path / "out" / "annotations.json").read_text())
    marks = {i["egonet"]["activity"]: i["egonet"] for i in coco["images"]}
    assert marks["gaze"]["depth"] == "predicted" and marks["gaze"]["intrinsics_assumed"] is True
    assert marks["room"]["depth"] == "measured" and "depth_model" not in marks["room"]


def test_score_reports_say_dhg_from_predicted_depth():
    with_predicted = Provenance(predicted_depth={"gaze": 3})
    assert ("Depth", "DHG from predicted depth: 3 frames (gaze 3), depth predicted from RGB by a network") in with_predicted.facts()
    assert with_predicted.as_dict()["predicted_depth_frames"] == {"gaze": 3}
    assert "DHG from predicted depth: 3 frames" in methods.paragraph([], with_predicted, activities=[], frames_per_activity={})
    assert "predicted depth" not in " ".join(t for _, t in Provenance().facts())


def test_a_queued_depth_run_is_the_worker_s_train_run_job(app, demo, runner, monkeypatch):
    queued = []
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: queued.append(run_id))
    args = ["egonet", "train-depth", "--queue", "--epochs", "1", "--size", "32x24", "--device", "cpu"]
    result = runner.invoke(args=args)
    assert result.exit_code == 0 and "queued: start `flask egonet worker`" in result.output
    result = runner.invoke(args=args)  # a second one, cancelled before the worker gets to it
    with app.app_context():
        first, second = sorted(queued)
        training.cancel_run(db.session.get(TrainingRun, second))
        assert training.execute_run(second).status is RunStatus.CANCELLED  # left alone, never trained
        run = training.execute_run(first)  # what the worker's job does
        assert run.status is RunStatus.DONE and [c.fold for c in run.checkpoints] == ["depth"]
        resumed = training.resume_run(db.session.get(TrainingRun, second))  # queued again, trained from the start
        assert resumed.status is RunStatus.QUEUED and queued[-1] == second
        assert training.execute_run(second).status is RunStatus.DONE
