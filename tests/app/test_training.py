"""Training runs: the service, the CLI, the pages and the prediction overlay.

Runs train egonet-lite on a few demo frames at 32x24 for one epoch: enough
to go through every step (folds, checkpoints, predictions), not to learn.
"""

import re

import numpy as np
import pytest

from app.extensions import db
from app.models import HAND_LABEL, Activity, Frame
from app.models.training import Checkpoint, FoldsMode, Prediction, RunStatus, TrainingEpoch, TrainingRun
from app.services import ground_truth, media, training
from app.services.scoring.sources import run_row_name
from app.services.demo import create_demo

TINY = {"model": "egonet-lite", "epochs": 1, "width": 32, "height": 24, "batch_size": 2, "device": "cpu"}


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


@pytest.fixture
def demo(app):
    """Two demo frames of each activity at 64x48, with reviewed ground truth; returns activity ids by name."""
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, width=64, height=48)
        return dict(db.session.execute(db.select(Activity.name, Activity.id)).all())


def two_activities(demo) -> tuple[int, int]:
    return demo["cooking"], demo["dining"]


def newest_run() -> TrainingRun:
    return db.session.execute(db.select(TrainingRun).order_by(TrainingRun.id.desc())).scalars().first()


def held_out_ids(run: TrainingRun) -> list[int]:
    return [i for c in run.checkpoints for i in c.test_frame_ids]


def train_now(demo, **options) -> TrainingRun:
    request = training.RunRequest(**(TINY | {"activity_ids": two_activities(demo)} | options))
    return training.execute_run(training.create_run(request).id)


# --------------------------------------------------------------------------- the service


def test_a_run_records_a_checkpoint_per_fold_and_every_held_out_prediction(ctx, demo):
    run = train_now(demo)
    assert run.status is RunStatus.DONE and run.progress == 1.0 and run.finished_at is not None
    assert [c.fold for c in run.checkpoints] == ["cooking", "dining"]
    assert set(run.metrics["folds"]) == {"cooking", "dining"}
    assert set(run.metrics["mean"]) == {"max_f", "ap", "aop_max_f", "aop_ap"}
    for checkpoint in run.checkpoints:
        state = training.files.load(checkpoint.path)
        assert state["fold"] == checkpoint.fold and state["test_keys"] == checkpoint.test_frame_ids
        assert checkpoint.metrics["history"][0]["epoch"] == 1
    assert training.files.exists(f"run-{run.id}/config.json")
    # The scorer's interface: every held-out frame once, at its full size, in [0, 1].
    assert training.completed_runs() == [run]
    pairs = list(training.held_out_predictions(run))
    held_out = sorted(held_out_ids(run))
    assert sorted(frame.id for frame, _ in pairs) == held_out and len(held_out) == 4
    for frame, probability in pairs:
        assert isinstance(frame, Frame)
        assert probability.shape == (frame.height, frame.width) == (48, 64) and probability.dtype == np.float32
        assert 0.0 <= probability.min() and probability.max() <= 1.0


@pytest.mark.one_database
def test_deeplab_obj_learns_the_training_activities_object_classes_and_its_row_says_how_many(ctx, demo):
    run = train_now(demo, model="deeplab-obj")
    assert run.status is RunStatus.DONE, run.message
    labels = {}
    for frame in ground_truth.labelled_frames(two_activities(demo)):
        annotation = ground_truth.ground_truths([frame.id])[frame.id]
        labels.setdefault(frame.sequence.activity.name, set()).update(i.label.lower() for i in annotation.instances)
    assert any(HAND_LABEL in found for found in labels.values())  # the demo's hands are there, and are no class
    for checkpoint in run.checkpoints:
        other = next(a for a in labels if a != checkpoint.fold)
        options = training.files.load(checkpoint.path)["model"]["options"]
        assert options["classes"] == sorted(labels[other] - {HAND_LABEL})
        assert checkpoint.metrics["classes"] == len(options["classes"])
    counts = sorted({c.metrics["classes"] for c in run.checkpoints})
    n = str(counts[0]) if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
    assert run_row_name(run) == f"DeepLab-Obj, {n} classes (run {run.id})"
    assert len(list(training.held_out_predictions(run))) == 4


def test_stored_maps_are_the_engine_maps_to_16_bits(ctx, demo):
    run = train_now(demo, folds="single")
    (checkpoint,) = run.checkpoints
    made = training.predict(checkpoint, [db.session.get(Frame, i) for i in checkpoint.test_frame_ids], device="cpu")
    stored = dict(training.held_out_predictions(run))
    for prediction in made:
        assert prediction.held_out
        again = training.read_probability(prediction.path)
        assert np.abs(again - stored[prediction.frame]).max() <= 1 / 65535 + 1e-7
    # Predicting again replaces the checkpoint's earlier maps: still one per frame.
    assert db.session.execute(db.select(db.func.count(Prediction.id))).scalar_one() == len(made)


def test_completed_runs_are_the_done_ones_newest_first(ctx, demo):
    first = train_now(demo, folds="single")
    second = train_now(demo, folds="single")
    queued = training.create_run(training.RunRequest(**TINY))
    assert training.completed_runs() == [second, first]
    assert queued not in training.completed_runs()


@pytest.mark.parametrize(
    ("options", "field", "message"),
    [
        ({"model": "resnet"}, "model", "unknown name 'resnet'"),
        ({"epochs": 0}, "epochs", "epochs must be an integer"),
        ({"width": 4}, "size", "width must be an integer >= 8"),
        ({"folds": "kfold"}, "folds", "folds must be one of"),
        ({"lr": -1.0}, "lr", "lr must be a number"),
        ({"activity_ids": (999,)}, "activities", "no activity with id 999"),
        ({"model": "egonet", "pretrained": True}, "pretrained", "egonet-lite only"),
    ],
)
def test_bad_requests_name_the_field(ctx, demo, options, field, message):
    with pytest.raises(training.TrainingProblem, match=message) as info:
        training.create_run(training.RunRequest(**(TINY | options)))
    assert info.value.field == field
    assert db.session.execute(db.select(TrainingRun)).first() is None


def test_too_little_data_is_refused_before_queueing(ctx, demo):
    with pytest.raises(training.TrainingProblem, match="at least two activities") as info:
        training.create_run(training.RunRequest(**TINY, activity_ids=(demo["cooking"],)))
    assert info.value.field == "folds"


def test_no_ground_truth_at_all_says_what_to_do(ctx):
    with pytest.raises(training.TrainingProblem, match="flask egonet demo"):
        training.create_run(training.RunRequest(**TINY))


def test_frames_without_dhg_are_refused_for_models_that_read_it(ctx, demo, tmp_path):
    from app.services.importing import import_path
    from tests.app.factories import image_folder

    import_path(image_folder(tmp_path / "plain", n=2, masks=True), activity="plain")
    with pytest.raises(training.TrainingProblem, match="2 labelled frames have no DHG image"):
        training.create_run(training.RunRequest(**TINY))


def test_a_cancelled_run_stops_and_resumes_keeping_finished_folds(ctx, demo, monkeypatch):
    run = training.create_run(training.RunRequest(**TINY, activity_ids=two_activities(demo)))
    monkeypatch.setattr(training.job, "PROGRESS_INTERVAL_S", 0.0)

    def cancel_in_second_fold(progress):
        if progress.fold_index == 1 and progress.loss is not None:
            training.cancel_run(db.session.get(TrainingRun, run.id))

    run = training.execute_run(run.id, on_progress=cancel_in_second_fold)
    assert run.status is RunStatus.CANCELLED and [c.fold for c in run.checkpoints] == ["cooking"]
    with pytest.raises(Exception, match="cancelled already"):
        training.cancel_run(run)

    queued = []
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: queued.append(run_id))
    training.resume_run(run)
    assert run.status is RunStatus.QUEUED and queued == [run.id]
    run = training.execute_run(run.id)
    assert run.status is RunStatus.DONE and [c.fold for c in run.checkpoints] == ["cooking", "dining"]
    with pytest.raises(Exception, match="only failed or cancelled"):
        training.resume_run(run)


def test_a_failure_is_recorded_on_the_run(ctx, demo, monkeypatch):
    run = training.create_run(training.RunRequest(**TINY, activity_ids=two_activities(demo)))

    def broken(*args, **kwargs):
        raise RuntimeError("out of memory\nmore detail")

    monkeypatch.setattr("egonet.train.cross_validate", broken)
    with pytest.raises(RuntimeError):
        training.execute_run(run.id)
    db.session.refresh(run)
    assert run.status is RunStatus.FAILED and run.message == "failed: out of memory"


def test_a_run_cancelled_while_queued_is_never_trained(ctx, demo):
    run = training.create_run(training.RunRequest(**TINY, activity_ids=two_activities(demo)))
    training.cancel_run(run)
    assert training.execute_run(run.id).status is RunStatus.CANCELLED
    assert run.checkpoints == []


# --------------------------------------------------------------------------- the CLI


def test_cli_trains_predicts_and_resumes(app, demo, runner):
    args = ["egonet", "train", "--folds", "loao", "--epochs", "1", "--size", "32x24", "--batch-size", "2",
            "--device", "cpu", "--activities", "cooking", "--activities", "dining", "--name", "cli run"]
    result = runner.invoke(args=args)
    assert result.exit_code == 0, result.output
    assert re.search(r"run \d+ \(cli run\): done", result.output)
    assert re.search(r"cooking\s+MF \d\.\d{3}\s+AP \d\.\d{3}\s+\(action-object prior: MF \d\.\d{3}", result.output)
    assert "mean" in result.output and "Training" in result.output  # the progress bar's label

    with app.app_context():
        run = newest_run()
        assert run.status is RunStatus.DONE and run.created_by is None
        cooking = next(c for c in run.checkpoints if c.fold == "cooking")
        n_frames = db.session.execute(db.select(db.func.count(Frame.id))).scalar_one()

    result = runner.invoke(args=["egonet", "predict", str(cooking.id), "--device", "cpu"])
    assert result.exit_code == 0, result.output
    assert f"{n_frames} predictions stored, 2 of held-out frames" in result.output

    result = runner.invoke(args=["egonet", "train", "--resume", str(cooking.id), "--epochs", "2", "--device", "cpu"])
    assert result.exit_code == 0, result.output
    with app.app_context():
        resumed = newest_run()
        (checkpoint,) = resumed.checkpoints
        assert resumed.status is RunStatus.DONE and checkpoint.fold == "cooking" and checkpoint.epochs == 2
        assert resumed.config["resume_checkpoint"] == cooking.id


def test_cli_refuses_bad_options_in_one_line(app, demo, runner):
    cases = [
        (["--size", "32"], "use WIDTHxHEIGHT"),
        (["--activities", "nowhere"], "no activity named 'nowhere'"),
        (["--activities", "cooking"], "at least two activities"),
        (["--resume", "7"], "no checkpoint with id 7"),
        (["--model", "resnet"], "unknown name 'resnet'"),
    ]
    for extra, message in cases:
        result = runner.invoke(args=["egonet", "train", "--epochs", "1", *extra])
        assert result.exit_code != 0 and message in result.output, (extra, result.output)
        assert "Traceback" not in result.output
    result = runner.invoke(args=["egonet", "predict", "3"])
    assert result.exit_code != 0 and "no checkpoint with id 3" in result.output


def test_cli_queues_a_run_for_the_worker(app, demo, runner, monkeypatch):
    queued = []
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: queued.append(run_id))
    result = runner.invoke(args=["egonet", "train", "--queue", "--folds", "single", "--epochs", "1"])
    assert result.exit_code == 0, result.output
    with app.app_context():
        run = newest_run()
        assert run.status is RunStatus.QUEUED and queued == [run.id]
    assert f"run {run.id} queued" in result.output


# --------------------------------------------------------------------------- pages


def test_admins_start_runs_from_the_page(app, demo, admin_client, monkeypatch):
    queued = []
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: queued.append(run_id))
    page = admin_client.get("/training/")
    assert page.status_code == 200 and b"Start a run" in page.data
    form = {"model": "egonet-lite", "folds": "single", "epochs": "1", "device": "cpu", "width": "32", "height": "24",
            "batch_size": "2", "seed": "3", "name": "from the page"}
    response = admin_client.post("/training/runs", data=form)
    assert response.status_code == 302
    with app.app_context():
        run = newest_run()
        assert queued == [run.id] and run.name == "from the page" and run.status is RunStatus.QUEUED and run.seed == 3
        assert run.created_by.username == "admin" and run.config["train"]["width"] == 32
    page = admin_client.get("/training/")
    assert b"from the page" in page.data and f"Run {run.id} queued".encode() in page.data


def test_a_bad_form_is_shown_again_with_the_reason(app, demo, admin_client):
    response = admin_client.post("/training/runs", data={"model": "egonet-lite", "folds": "loao", "epochs": "0", "device": "cpu",
                                                         "width": "32", "height": "24", "batch_size": "2", "seed": "0",
                                                         "activities": [str(demo["cooking"])]})
    assert response.status_code == 400 and b"Number must be between 1" in response.data
    response = admin_client.post("/training/runs", data={"model": "egonet-lite", "folds": "loao", "epochs": "1", "device": "cpu",
                                                         "width": "32", "height": "24", "batch_size": "2", "seed": "0",
                                                         "activities": [str(demo["cooking"])]})
    assert response.status_code == 400 and b"at least two activities" in response.data
    with app.app_context():
        assert db.session.execute(db.select(TrainingRun)).first() is None


def test_annotators_see_runs_but_cannot_start_them(app, demo, client, make_user):
    client.login_as(make_user("annotator"))
    page = client.get("/training/")
    assert page.status_code == 200 and b"Start a run" not in page.data
    assert client.post("/training/runs", data={"model": "egonet-lite"}).status_code == 403


def test_progress_is_polled_as_json_and_runs_are_cancelled_from_the_page(app, demo, admin_client, monkeypatch):
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: None)
    with app.app_context():
        run_id = training.create_run(training.RunRequest(**TINY, activity_ids=two_activities(demo))).id
    body = admin_client.get(f"/training/status?ids={run_id}").get_json()
    assert body["runs"][0] | {"updated_at": None} == {
        "id": run_id, "status": "queued", "progress": 0.0, "loss": None, "eta_s": None, "message": None, "mean": {}, "updated_at": None,
    }
    assert admin_client.get("/training/status?ids=x", headers={"Accept": "application/json"}).get_json()["fields"] == {"ids": "must be an integer"}
    assert admin_client.post(f"/training/runs/{run_id}/cancel").status_code == 302
    response = admin_client.post(f"/training/runs/{run_id}/cancel", headers={"Accept": "application/json"})
    assert response.status_code == 409 and "cancelled already" in response.get_json()["message"]
    page = admin_client.get(f"/training/runs/{run_id}")
    assert page.status_code == 200 and b"Resume" in page.data and b"cancelled" in page.data


def test_run_page_shows_folds_and_the_frame_viewer_shows_the_heatmap(app, demo, admin_client):
    with app.app_context():
        run = train_now(demo)
        frame_id = run.checkpoints[0].test_frame_ids[0]
        held_out = held_out_ids(run)
        prediction_id = db.session.execute(db.select(Prediction.id).where(Prediction.frame_id == frame_id)).scalar_one()
    page = admin_client.get(f"/training/runs/{run.id}")
    assert page.status_code == 200
    assert b"Held-out predictions" in page.data and b"cooking" in page.data and b'id="folds"' in page.data
    viewer = admin_client.get(f"/frames/{frame_id}")
    assert f"/training/predictions/{prediction_id}.png".encode() in viewer.data and b'id="show-prediction"' in viewer.data
    with admin_client.get(f"/training/predictions/{prediction_id}.png") as overlay:
        assert overlay.status_code == 200 and overlay.mimetype == "image/png"
        import cv2

        image = cv2.imdecode(np.frombuffer(overlay.data, np.uint8), cv2.IMREAD_UNCHANGED)
        assert image.shape == (48, 64, 4)  # colour and opacity at the frame's size
    with app.app_context():
        other = db.session.execute(db.select(Frame.id).where(Frame.id.notin_(held_out))).scalars().first()
    assert b'id="show-prediction"' not in admin_client.get(f"/frames/{other}").data


def test_cli_predict_chooses_frames_and_can_queue(app, demo, runner, monkeypatch):
    with app.app_context():
        run = train_now(demo, folds="single")
        checkpoint_id = run.checkpoints[0].id
        dining = sorted(f.id for f in training.frames_for_prediction(activity_names=["dining"]))
    queued = []
    monkeypatch.setattr("app.tasks.predict_frames", lambda *args: queued.append(args))
    result = runner.invoke(args=["egonet", "predict", str(checkpoint_id), "--activity", "dining", "--queue", "--device", "cpu"])
    assert result.exit_code == 0, result.output
    assert queued == [(checkpoint_id, dining, "cpu")] and "2 frames queued" in result.output
    result = runner.invoke(args=["egonet", "predict", str(checkpoint_id), "--frames", f"{dining[0]}", "--device", "cpu"])
    assert result.exit_code == 0 and "1 predictions stored" in result.output
    for extra, message in ((["--activity", "nowhere"], "no activity named 'nowhere'"), (["--frames", "99999"], "no frame with id 99999"),
                           (["--frames", "a,b"], "give frame ids separated by commas")):
        result = runner.invoke(args=["egonet", "predict", str(checkpoint_id), *extra])
        assert result.exit_code != 0 and message in result.output, result.output


# --------------------------------------------------------------------------- inspecting runs: history, frames, files


def hand_made_run(*, status=RunStatus.DONE, name="hand made", tags=(), folds=("cooking",), frame=None, path=None) -> TrainingRun:
    """A run with a checkpoint file and epoch rows per fold, and a held-out prediction of ``frame`` (no training)
    stored at ``path`` (a media path) or in a file of its own."""
    from egonet import io

    run = TrainingRun(name=name, model_name="egonet-lite", folds=FoldsMode.LOAO, epochs=2, device="cpu",
                      seed=0, config={"train": {"width": 32}}, status=status, tags=list(tags))
    db.session.add(run)
    db.session.flush()
    for fold in folds:
        checkpoint = Checkpoint(run=run, fold=fold, path=f"run-{run.id}/{fold}.pt", epochs=2,
                                metrics={"max_f": 0.5, "aop_max_f": 0.4, "threshold": 0.3},
                                test_frame_ids=[frame.id] if frame is not None else [])
        training.files.put(checkpoint.path, f"weights of {fold}".encode())
        db.session.add(checkpoint)
        training.history.record_epochs(run.id, fold, [{"epoch": 1, "train_loss": 0.7, "lr": 0.02, "loss": 0.6, "max_f": 0.3},
                                                      {"epoch": 2, "train_loss": 0.5, "lr": 0.01, "loss": 0.55, "max_f": 0.5}])
        if frame is not None:
            probability = np.full((frame.height, frame.width), 0.25, np.float32)
            path = path or media.store(io.encode_probability_png(probability), ".png")
            db.session.add(Prediction(run=run, checkpoint=checkpoint, frame_id=frame.id, held_out=True, path=path))
    db.session.commit()
    return run


def test_per_frame_scores_by_hand():
    from egonet.metrics import count_stats

    from app.services.training.predictions import scores_at

    prob = np.array([[0.9, 0.4], [0.2, 0.0]], np.float32)
    truth = np.array([[True, True], [False, False]])
    counts = count_stats(prob, truth)
    assert scores_at(counts, 0.5) == pytest.approx((2 / 3, 1.0, 0.5))  # one of the two object pixels reaches 0.5
    assert scores_at(counts, 0.3) == pytest.approx((1.0, 1.0, 1.0))
    assert scores_at(counts, 0.15) == pytest.approx((0.8, 2 / 3, 1.0))
    empty = count_stats(prob, np.zeros((2, 2), bool))
    assert scores_at(empty, 0.95) == (1.0, 1.0, None)  # no object, nothing predicted: right
    assert scores_at(empty, 0.5) == (0.0, 0.0, None)


def test_history_is_paged_after_the_last_row_seen_and_bounded(app, ctx, admin_client, monkeypatch):
    runs = [hand_made_run(name=f"run {i}", folds=("cooking", "dining")) for i in range(2)]
    ids = ",".join(str(r.id) for r in runs)
    monkeypatch.setattr(training.history, "PAGE_ROWS", 3)
    seen, after = [], 0
    while True:
        body = admin_client.get(f"/training/history?runs={ids}&after={after}").get_json()
        seen += body["epochs"]
        after = body["after"]
        if not body["more"]:
            break
    assert len(seen) == 8 and len({r["id"] for r in seen}) == 8 and {r["run"] for r in seen} == {r.id for r in runs}
    assert [r["name"] for r in body["runs"]] == ["run 0", "run 1"]
    assert body["runs"][0]["folds"]["cooking"] == {"aop_max_f": 0.4, "max_f": 0.5, "epochs": 2}
    assert admin_client.get(f"/training/history?runs={ids}&after={after}").get_json()["epochs"] == []
    # A record written again comes again, with a newer id.
    training.history.record_epochs(runs[0].id, "cooking", [{"epoch": 2, "train_loss": 0.45}])
    db.session.commit()
    (again,) = admin_client.get(f"/training/history?runs={ids}&after={after}").get_json()["epochs"]
    assert (again["fold"], again["epoch"], again["train_loss"]) == ("cooking", 2, 0.45) and again["id"] > after
    # The Training page ticks the runs of ?compare=, else the newest three with a history.
    checked = lambda html: re.findall(r'class="compare-run" value="(\d+)"[^>]*checked', html)  # noqa: E731
    assert checked(admin_client.get(f"/training/?compare={runs[0].id}").data.decode()) == [str(runs[0].id)]
    assert sorted(checked(admin_client.get("/training/").data.decode())) == sorted(str(r.id) for r in runs)
    for query, field in (("runs=a,b", "runs"), ("runs=" + ",".join(map(str, range(1, 14))), "runs"), ("runs=1&after=-3", "after"),
                         ("runs=1&after=99999999999999999999", "after"), ("runs=0", "runs")):
        response = admin_client.get(f"/training/history?{query}", headers={"Accept": "application/json"})
        assert response.status_code == 400 and field in response.get_json()["fields"], query


def test_admins_rename_and_tag_with_a_version_check(app, ctx, admin_client, make_user):
    run = hand_made_run()
    form = {"name": "lite baseline", "tags": "baseline, lite 160, baseline", "version": "1"}
    assert admin_client.post(f"/training/runs/{run.id}/edit", data=form).status_code == 302
    db.session.refresh(run)
    assert (run.name, run.tags, run.version) == ("lite baseline", ["baseline", "lite 160"], 2)
    # A second admin's edit based on the version they loaded is refused, and says what is there now.
    stale = admin_client.post(f"/training/runs/{run.id}/edit", data=form | {"name": "mine", "tags": ""})
    assert stale.status_code == 409 and b"changed by someone else" in stale.data and b"lite baseline" in stale.data
    db.session.refresh(run)
    assert run.name == "lite baseline" and run.version == 2
    bad = admin_client.post(f"/training/runs/{run.id}/edit", data=form | {"version": "2", "tags": "ok, no<script>"})
    assert bad.status_code == 400 and b"tag" in bad.data
    assert admin_client.post(f"/training/runs/{run.id}/edit", data={"tags": "x", "version": "2"}).status_code == 400
    other = hand_made_run(name="untagged")
    page = admin_client.get("/training/?tag=baseline").data
    assert b"lite baseline" in page and b"untagged" not in page
    assert b"untagged" in admin_client.get("/training/").data
    # Only admins edit: the access matrix checks every other role gets 403.


@pytest.mark.both_storages
def test_staff_download_checkpoints_and_configuration(app, ctx, client, make_user, tmp_path):
    run = hand_made_run(folds=("desk work",))
    (checkpoint,) = run.checkpoints
    client.login_as(make_user("annotator"))
    with client.get(f"/training/checkpoints/{checkpoint.id}/download") as response:
        assert response.status_code == 200 and response.mimetype == "application/octet-stream"
        assert response.headers["Content-Disposition"] == f"attachment; filename=run-{run.id}-desk-work-e2.pt"
        assert response.data == b"weights of desk work"
    with client.get(f"/training/runs/{run.id}/config.json") as response:
        assert response.headers["Content-Disposition"] == f'attachment; filename="run-{run.id}-config.json"'
        body = response.get_json()
        assert body["config"] == {"train": {"width": 32}} and body["checkpoints"][0]["fold"] == "desk work"
    training.files.delete(checkpoint.path)
    response = client.get(f"/training/checkpoints/{checkpoint.id}/download", headers={"Accept": "application/json"})
    assert response.status_code == 404 and "missing on the server" in response.get_json()["message"]


def test_a_queued_or_running_run_cannot_be_deleted(app, ctx, admin_client):
    run = hand_made_run(status=RunStatus.RUNNING)
    page = admin_client.get(f"/training/runs/{run.id}/delete")
    assert page.status_code == 409 and b"cancel it first" in page.data and b"confirm-delete" not in page.data
    assert admin_client.post(f"/training/runs/{run.id}/delete").status_code == 409
    assert db.session.get(TrainingRun, run.id) is not None
    assert training.files.listing(f"run-{run.id}")


def test_the_migration_copies_the_history_of_older_runs(ctx):
    import sqlalchemy as sa
    from flask_migrate import downgrade, upgrade

    downgrade(revision="0006")
    try:
        with db.engine.begin() as conn:
            conn.execute(sa.text(
                "INSERT INTO training_run (id, name, model_name, model_options, folds, epochs, device, seed, config, status, progress,"
                " metrics, created_at, updated_at) VALUES (7, 'old', 'egonet-lite', '{}', 'single', 2, 'cpu', 0, '{}', 'done', 1,"
                " '{}', '2026-01-01 00:00:00', '2026-01-01 00:00:00')"))
            history = '{"max_f": 0.5, "history": [{"epoch": 1, "train_loss": 0.6, "lr": 0.02, "max_f": 0.4}, {"epoch": 2, "train_loss": 0.5, "lr": 0.01, "loss": 0.55, "max_f": 0.5, "ap": 0.45}]}'
            conn.execute(sa.text(
                "INSERT INTO training_checkpoint (id, run_id, fold, path, epochs, metrics, test_frame_ids, created_at)"
                " VALUES (3, 7, 'single', 'run-7/single.pt', 2, :m, '[]', '2026-01-01 00:00:00')"), {"m": history})
    finally:
        upgrade()
    run = db.session.get(TrainingRun, 7)
    assert run.tags == [] and run.version == 1
    rows = training.chart_data([7])["epochs"]
    assert [(r["fold"], r["epoch"], r["train_loss"], r["max_f"], r["ap"]) for r in rows] == [
        ("single", 1, 0.6, 0.4, None), ("single", 2, 0.5, 0.5, 0.45)]


@pytest.mark.slow
def test_inspect_a_trained_run_then_delete_it_leaving_nothing_behind(app, demo, admin_client, runner):
    """A real tiny run: epochs recorded as they end, per-frame scores, the frames page, then deletion."""
    from app.models import Annotation
    from app.services.ground_truth import ground_truths, mask_of

    seen_live = []
    with app.app_context():
        run = training.create_run(training.RunRequest(**(TINY | {"epochs": 2, "activity_ids": two_activities(demo)})))

        def watch(progress):  # while the second fold trains, the first fold's epochs are already rows
            if progress.fold_index == 1 and not seen_live:
                seen_live.extend(db.session.execute(db.select(TrainingEpoch.fold, TrainingEpoch.epoch)).all())

        run = training.execute_run(run.id, on_progress=watch)
        assert sorted(seen_live) == [("cooking", 1), ("cooking", 2)]
        rows = training.chart_data([run.id])["epochs"]
        assert sorted((r["fold"], r["epoch"]) for r in rows) == [("cooking", 1), ("cooking", 2), ("dining", 1), ("dining", 2)]
        for checkpoint in run.checkpoints:
            last = next(r for r in rows if r["fold"] == checkpoint.fold and r["epoch"] == 2)
            assert last["max_f"] == pytest.approx(checkpoint.metrics["max_f"]) and last["loss"] is not None
            first = next(r for r in rows if r["fold"] == checkpoint.fold and r["epoch"] == 1)
            assert first["max_f"] is not None and first["train_loss"] > 0
        # Per-frame F at the fold's threshold, checked against the stored map and the truth directly.
        predictions = db.session.execute(db.select(Prediction).where(Prediction.run_id == run.id)).scalars().all()
        truths = ground_truths([p.frame_id for p in predictions])
        for p in predictions:
            t = p.checkpoint.metrics["threshold"]
            predicted = training.read_probability(p.path).astype(np.float64) >= t - 1e-9
            truth = mask_of(truths[p.frame_id])
            tp = (predicted & truth).sum()
            f = 2 * tp / (predicted.sum() + truth.sum()) if predicted.sum() + truth.sum() else 1.0
            # The job scored the float map, this the stored 16-bit one: a pixel within 2e-5 of t may differ.
            assert p.f_score == pytest.approx(f, abs=0.02), p.frame_id
        recorded = {p.id: p.f_score for p in predictions}
        order = [p.frame_id for p in sorted(predictions, key=lambda p: (p.f_score, p.frame_id))]
        # Runs recorded before per-frame scores: the page offers to score them, the job does.
        for p in predictions:
            p.f_score = None
        db.session.commit()
        run_id, prediction_id = run.id, predictions[0].id
        annotation = db.session.execute(db.select(Annotation)).scalars().first()
        annotation.proposed_by_run_id, annotation.proposed_by_checkpoint_id = run.id, run.checkpoints[0].id
        db.session.commit()
        annotation_id = annotation.id

    page = admin_client.get(f"/training/runs/{run_id}/frames")
    assert b"have no per-frame score yet" in page.data
    from app import tasks

    with app.app_context():
        assert tasks.score_frames.func(run_id) == len(recorded)
        rescored = {p.id: p.f_score for p in db.session.execute(db.select(Prediction)).scalars()}
    assert rescored == pytest.approx(recorded, abs=0.02)
    page = admin_client.get(f"/training/runs/{run_id}/frames").data.decode()
    listed = [int(x) for x in re.findall(r'class="frame-row" data-frame="(\d+)"', page)]
    assert listed == order and "no per-frame score" not in page
    assert "dining" in admin_client.get(f"/training/runs/{run_id}/frames?fold=dining").data.decode()
    assert admin_client.get(f"/training/runs/{run_id}/frames?fold=nowhere").status_code == 404
    for kind in ("prediction", "truth"):
        with admin_client.get(f"/training/predictions/{prediction_id}/{kind}.png") as picture:
            assert picture.status_code == 200 and picture.mimetype == "image/png"
    assert admin_client.get(f"/training/predictions/{prediction_id}/other.png").status_code == 404

    assert f"(run {run_id})" in admin_client.get("/scores/").data.decode()
    # Delete: the confirmation says what goes; afterwards nothing is left and nothing is orphaned.
    with app.app_context():
        paths = sorted(db.session.execute(db.select(Prediction.path).where(Prediction.run_id == run_id)).scalars())
        # Media are content-addressed: another run's row may name the same file, which must stay.
        hand_made_run(name="kept", frame=db.session.get(Frame, order[0]), path=paths[0])
        files = [media.local_path(p) for p in paths[1:]]
        kept_files = [media.local_path(paths[0])]
        assert training.files.listing(f"run-{run_id}") and all(f.exists() for f in files)
    confirm = admin_client.get(f"/training/runs/{run_id}/delete").data.decode()
    assert "2 checkpoints" in confirm and f"{len(paths)} predictions and {len(files)} media files" in confirm
    assert "4 epoch records" in confirm
    assert "proposed by run" in confirm
    response = admin_client.post(f"/training/runs/{run_id}/delete")
    assert response.status_code == 302
    listing = admin_client.get("/training/").data.decode()
    assert "deleted with 2 checkpoints" in listing, re.findall(r"class=\"flash[^<]*", listing)
    with app.app_context():
        for model in (TrainingRun, Checkpoint, Prediction, TrainingEpoch):
            assert db.session.execute(db.select(model).where(model.run_id == run_id if model is not TrainingRun
                                                             else model.id == run_id)).first() is None
        annotation = db.session.get(Annotation, annotation_id)
        assert annotation.proposed_by_run_id is None and annotation.proposed_by_checkpoint_id is None
    with app.app_context():
        assert not training.files.listing(f"run-{run_id}")
    assert not any(f.exists() for f in files) and all(f.exists() for f in kept_files)
    result = runner.invoke(args=["egonet", "media-check"])
    assert result.exit_code == 0 and " 0 missing, 0 orphaned" in result.output, result.output
    assert admin_client.get(f"/training/runs/{run_id}").status_code == 404
    scores = admin_client.get("/scores/")
    assert scores.status_code == 200 and f"(run {run_id})" not in scores.data.decode()
    assert admin_client.get(f"/scores/?runs={run_id}&chosen=1").status_code < 500


def test_the_frames_page_sorts_worst_first_in_pages(ctx, demo):
    frames = db.session.execute(db.select(Frame).order_by(Frame.id)).scalars().all()[:5]
    run = hand_made_run(folds=("cooking",))
    (checkpoint,) = run.checkpoints
    for frame, f in zip(frames, (0.9, None, 0.1, 0.5, 0.1), strict=True):
        db.session.add(Prediction(run=run, checkpoint=checkpoint, frame=frame, path=f"xx/{frame.id}.png", held_out=True, f_score=f))
    db.session.commit()
    pages = [training.frame_page(run, page=n, per_page=2) for n in (1, 2, 3, 9)]
    assert [[p.f_score for p in page.predictions] for page in pages] == [[0.1, 0.1], [0.5, 0.9], [None], [None]]
    assert [p.frame_id for p in pages[0].predictions] == [frames[2].id, frames[4].id]  # ties by frame id
    assert (pages[0].total, pages[0].pages, pages[3].page, pages[0].unscored) == (5, 3, 3, 1)
    assert training.frame_page(run, fold="dining").total == 0
