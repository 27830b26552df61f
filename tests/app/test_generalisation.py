"""Beyond the training set (the paper's Tables 3 and 4): a run on every frame of some activities, scored on others.

``train --folds all`` trains one model on every labelled frame of its
activities; its predictions of other activities' frames are held out, its
own activities' are not. ``score --trained-on A --trained-on B`` makes the
table of that training set: its runs, the learned baselines fitted on A and
B (never on the scored activities), the other activities as columns, and
every format saying so.
"""

import csv
import io
import json
import re

import numpy as np
import pytest

from app.extensions import db
from app.models import Activity, Status
from app.models.training import FoldsMode, Prediction, RunStatus, TrainingRun
from app.services import scoring, training
from app.services.demo import create_demo
from app.services.importing import FrameItem, add_frames
from app.services.scoring import fitting
from app.services.scoring import sources as scoring_sources
from app.queue import current_huey
from app.tasks import score_baselines
from egonet.baselines import BASELINES, ActionObjectPrior, TrainingFrame
from egonet.metrics import score_maps
from tests.app.test_scoring import SIZE, add_activity, assert_cell, frames_by_activity, make_run, rgb_of, row, stored_prediction, truth_mask

TRAINED_ON = ["cooking", "hotel"]


def make_all_run(name: str, *, trained_on: list[str], seed: int = 0) -> TrainingRun:
    """A done run on every frame of ``trained_on``: held-out predictions on every other activity's frames."""
    ids = dict(db.session.execute(db.select(Activity.name, Activity.id)).all())
    others = [a for a in frames_by_activity() if a not in trained_on]
    run = make_run(name, held_out=others, seed=seed,
                   config={"activities": sorted(trained_on), "activity_ids": sorted(ids[a] for a in trained_on)})
    run.folds = FoldsMode.ALL
    db.session.commit()
    return run


@pytest.mark.slow  # fits the five learned baselines
def test_a_table_trained_on_some_activities_scores_the_others_with_baselines_fitted_on_the_same(ctx):
    for seed, name in enumerate(("cooking", "hotel", "desk work")):
        add_activity(name, seed=seed)
    everywhere = make_all_run("lite on two", trained_on=TRAINED_ON, seed=5)
    loao = make_run("lite loao", held_out=["cooking", "hotel", "desk work"], seed=3)

    report = scoring.build_report(trained_on=["hotel", "cooking"], study_ids=[])
    assert report.activities == ["desk work"]  # the training activities are no columns
    models = [r for r in report.rows if r.kind == "model"]
    assert [r.key for r in models] == [f"run:{everywhere.id}"]  # the leave-one-activity-out run is another table's
    assert models[0].detail == "lite on two, trained on: cooking, hotel, seed 5"
    assert report.provenance.trained_on == ("cooking", "hotel") and report.provenance.training_frames == {"cooking": 3, "hotel": 3}
    assert report.provenance.model_splits == {f"run:{everywhere.id}": "all"}

    frames = frames_by_activity()
    masks = {a: [truth_mask(f) for f in fs] for a, fs in frames.items()}
    rgbs = {a: [rgb_of(f) for f in fs] for a, fs in frames.items()}
    # The run: its held-out maps of desk work, scored directly.
    expected = score_maps([stored_prediction(everywhere, f) for f in frames["desk work"]], masks["desk work"])
    assert_cell(models[0].cells["desk work"], expected, 3)
    # The learned baselines: fitted on cooking and hotel (what the run was trained on), never on desk work.
    learned = {r.name for r in report.rows if r.detail == "trained on: cooking, hotel"}
    assert learned == {"Judd", "Handled+Viewed-Obj (hands: skin colour)", "AOP", "FP-MCG", "salObj+depth"}
    training_frames = [TrainingFrame(rgb, None, m) for a in TRAINED_ON for rgb, m in zip(rgbs[a], masks[a])]
    for key in ("aop", "judd"):
        model = BASELINES[key]().fit(training_frames)
        expected = score_maps([model.predict(rgb) for rgb in rgbs["desk work"]], masks["desk work"])
        assert_cell(row(report, BASELINES[key].name).cells["desk work"], expected, 3)
    leaky = ActionObjectPrior().fit_masks([m for ms in masks.values() for m in ms])  # one that saw desk work
    leaky_ap = score_maps([leaky.predict(rgb) for rgb in rgbs["desk work"]], masks["desk work"]).ap
    assert row(report, "AOP").cells["desk work"].ap != pytest.approx(leaky_ap, abs=1e-3)
    # The fitted fold on disk: one for the table, its training frames those of cooking and hotel only.
    truth = scoring_sources.load_truth(TRAINED_ON)
    key = fitting.fold_key("aop", truth, "desk work")
    assert key["trained_on"] == TRAINED_ON and key["frames"] == 6 and "held_out" not in key
    assert {truth.activity[f.id] for f in truth.training_frames("desk work")} == set(TRAINED_ON)
    assert fitting.fold_path("aop", truth, "desk work").exists()

    # Every format says what the table was trained on.
    data = json.loads(report.to_json())
    assert data["trained_on"] == {"activities": TRAINED_ON, "frames": {"cooking": 3, "hotel": 3}}
    got = next(r for r in data["rows"] if r["key"] == f"run:{everywhere.id}")
    assert "trained on: cooking, hotel" in got["detail"] and set(got["cells"]) == {"desk work"}
    lines = list(csv.DictReader(io.StringIO(report.to_csv())))
    assert {line["trained on"] for line in lines} == {"cooking, hotel"} and len(lines) == 1 + 8  # the run and the baselines
    latex = report.to_latex()
    assert "% Training set: trained on: cooking, hotel (6 labelled frames: cooking 3, hotel 3)" in latex
    methods = report.to_methods()
    assert "Every model and learned baseline was trained on the 6 labelled frames of cooking and hotel (cooking 3, hotel 3) only" in methods
    assert "one training run, trained on every labelled frame of the training activities, none held out" in methods
    assert "fitted once, on the training activities' labelled frames" in methods and "leave-one-activity-out" not in methods

    # Table 2 (no training set) leaves the run out and says where it is; the loao run and LOAO baselines are there.
    table2 = scoring.build_report(study_ids=[], baselines=False)
    assert [r.key for r in table2.rows] == [f"run:{loao.id}"] and table2.activities == ["cooking", "desk work", "hotel"]
    assert f"Runs {everywhere.id} trained on every frame of cooking, hotel are in the table trained on them, not in this one." in table2.notes
    # Choosing the run alone infers its training set.
    alone = scoring.build_report(run_ids=[everywhere.id], study_ids=[], baselines=False)
    assert alone.provenance.trained_on == ("cooking", "hotel") and alone.activities == ["desk work"]


def test_one_table_one_training_set(ctx):
    for seed, name in enumerate(("cooking", "hotel", "desk work")):
        add_activity(name, seed=seed)
    everywhere = make_all_run("lite on two", trained_on=TRAINED_ON)
    other = make_all_run("lite on one", trained_on=["cooking"])
    loao = make_run("lite loao", held_out=["cooking"], seed=3)
    with pytest.raises(scoring.ScoringProblem, match=rf"run {loao.id} \(loao folds\) is not a row of the table trained on cooking, hotel") as err:
        scoring.build_report(trained_on=TRAINED_ON, run_ids=[loao.id], study_ids=[])
    assert err.value.field == "runs"
    with pytest.raises(scoring.ScoringProblem, match=rf"different activities \(run {everywhere.id}: cooking, hotel; run {other.id}: cooking\): a table has one training set") as err:
        scoring.build_report(run_ids=[everywhere.id, other.id], study_ids=[])
    assert err.value.field == "runs"
    with pytest.raises(scoring.ScoringProblem, match=rf"run {other.id} was trained on every frame of cooking: it is not a row of the table trained on cooking, hotel") as err:
        scoring.build_report(trained_on=TRAINED_ON, run_ids=[other.id], study_ids=[])
    with pytest.raises(scoring.ScoringProblem, match="trained_on: no activity named 'garden'") as err:
        scoring.build_report(trained_on=["cooking", "garden"], study_ids=[])
    assert err.value.field == "trained_on"
    # The other set's table: its run only, and desk work and hotel as columns.
    report = scoring.build_report(trained_on=["cooking"], study_ids=[], baselines=False)
    assert [r.key for r in report.rows] == [f"run:{other.id}"] and report.activities == ["desk work", "hotel"]
    assert scoring.training_sets() == {("cooking",): [other.id], ("cooking", "hotel"): [everywhere.id]}


# --------------------------------------------------------------------------- trained for real, from the command line


@pytest.fixture
def demo(app):
    """Two demo frames of each activity at 64x48, reviewed."""
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, width=64, height=48)


@pytest.mark.slow
@pytest.mark.usefixtures("one_thread")
def test_train_on_all_frames_predict_elsewhere_and_score_from_the_command_line(app, demo, runner, admin_client):
    args = ["egonet", "train", "--folds", "all", "--epochs", "1", "--size", "32x24", "--batch-size", "2", "--device", "cpu",
            "--activities", "cooking", "--activities", "dining", "--name", "on two"]  # fmt: skip
    result = runner.invoke(args=args)
    assert result.exit_code == 0, result.output
    with app.app_context():
        run = db.session.execute(db.select(TrainingRun).order_by(TrainingRun.id.desc())).scalars().first()
        (checkpoint,) = run.checkpoints
        assert run.status is RunStatus.DONE and run.folds is FoldsMode.ALL and checkpoint.fold == "all"
        assert checkpoint.test_frame_ids == [] and checkpoint.metrics["train_frames"] == 4
        assert training.trained_on(run) == ["cooking", "dining"] and run.metrics["mean"] == {}
        assert db.session.execute(db.select(Prediction).where(Prediction.run_id == run.id)).first() is None
    assert f"trained on: cooking, dining; no frame held out. Score it elsewhere: `flask egonet predict {checkpoint.id}" in result.output
    assert "MF -" not in result.output  # no empty line of held-out scores
    page = admin_client.get(f"/training/runs/{run.id}").get_data(as_text=True)
    assert "Trained on every labelled frame of cooking, dining, none held out" in page
    assert f"flask egonet predict {checkpoint.id} --activity NAME" in page and "/scores/?trained_on=cooking&amp;trained_on=dining" in page

    result = runner.invoke(args=["egonet", "predict", str(checkpoint.id), "--activity", "hotel", "--activity", "cooking", "--device", "cpu"])
    assert result.exit_code == 0, result.output
    assert "4 predictions stored, 2 of held-out frames" in result.output
    with app.app_context():
        predictions = db.session.execute(db.select(Prediction).where(Prediction.run_id == run.id)).scalars()
        held = {(p.frame.sequence.activity.name, p.held_out) for p in predictions}
        assert held == {("hotel", True), ("cooking", False)}  # its own training frames are never held out
        scored = {p.held_out: p.f_score is not None for p in db.session.execute(
            db.select(Prediction).where(Prediction.run_id == run.id)).scalars()}  # fmt: skip
        assert scored == {True: True, False: False}  # held-out maps get their per-frame F (at 0.5: no fold threshold)

    result = runner.invoke(args=["egonet", "score", "--format", "json", "--studies", "", "--trained-on", "cooking",
                                 "--trained-on", "dining", "--resamples", "100"])  # fmt: skip
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    got = next(r for r in data["rows"] if r["key"] == f"run:{run.id}")
    assert got["detail"] == "on two, trained on: cooking, dining, seed 0" and set(got["cells"]) == {"hotel"}
    assert got["cells"]["hotel"]["n_frames"] == 2
    aop = next(r for r in data["rows"] if r["key"] == "baseline:aop")
    assert aop["detail"] == "trained on: cooking, dining"
    # Only the activities the run never saw are columns: the baselines are scored there too.
    assert {a for r in data["rows"] for a in r["cells"]} == {"desk work", "dishwashing", "grocery", "hotel", "shopping"}
    assert data["trained_on"] == {"activities": ["cooking", "dining"], "frames": {"cooking": 2, "dining": 2}}

    result = runner.invoke(args=["egonet", "report", "--methods", "--studies", "", "--no-baselines", "--runs", str(run.id)])
    assert result.exit_code == 0, result.output
    assert "trained on the 4 labelled frames of cooking and dining (cooking 2, dining 2) only" in result.output
    result = runner.invoke(args=["egonet", "score", "--trained-on", "garden"])
    assert result.exit_code != 0 and "no activity named 'garden'" in result.output


def test_the_training_form_offers_all_frames(app, admin_client):
    page = admin_client.get("/training/")
    assert page.status_code == 200
    assert re.search(rb'<option value="all"[^>]*>all frames, none held out', page.data)


def test_the_score_page_shows_the_training_sets_and_the_table_of_one(app, admin_client):
    with app.app_context():
        for seed, name in enumerate(("cooking", "hotel", "desk work")):
            add_activity(name, seed=seed)
        run_id = make_all_run("lite on two", trained_on=TRAINED_ON).id
    page = admin_client.get("/scores/?chosen=1&runs=&studies=")  # Table 2, nothing chosen: links to the set
    assert page.status_code == 200
    assert b'href="/scores/?trained_on=cooking&amp;trained_on=hotel"' in page.data
    page = admin_client.get(f"/scores/?trained_on=cooking&trained_on=hotel&chosen=1&runs={run_id}&studies=")
    text = page.get_data(as_text=True)
    assert page.status_code == 200 and 'id="trained-on"' in text and "Trained on: <strong>cooking, hotel</strong>" in text
    assert f'data-row="run:{run_id}"' in text and '<input type="hidden" name="trained_on" value="hotel">' in text
    assert '<input type="radio" name="columns" value="sequences">' in text  # recordings as columns, offered
    download = admin_client.get(f"/scores/table.csv?trained_on=cooking&trained_on=hotel&chosen=1&runs={run_id}&studies=")
    assert download.status_code == 200 and "cooking, hotel" in download.get_data(as_text=True)
    bad = admin_client.get("/scores/?trained_on=garden")
    assert bad.status_code == 400 and b"no activity named" in bad.data


def add_videos(activity: str, videos: list[str], *, n: int = 3) -> None:
    """``n`` labelled frames in each of the activity's recordings (sequences), a box a little further right in each."""
    rng = np.random.default_rng(7)
    for v, video in enumerate(videos):
        items = []
        for i in range(n):
            mask = np.zeros(SIZE, bool)
            mask[10 + i : 30, 10 + 8 * v : 30 + 8 * v] = True
            rgb = rng.integers(0, 255, (*SIZE, 3), dtype=np.uint8)
            rgb[mask] //= 3
            items.append(FrameItem(f"{video}-{i}", i, f"test {video} {i}", rgb=rgb, mask=mask, meta={"kind": "visual"}))
        add_frames(activity=activity, sequence=video, items=iter(items), mask_status=Status.REVIEWED)


@pytest.mark.slow  # fits the five learned baselines
def test_a_datasets_videos_imported_as_one_activity_are_the_columns(ctx):
    """Table 3's layout: the videos of a dataset imported as one activity, each a column, resampled on its own."""
    for seed, name in enumerate(TRAINED_ON):
        add_activity(name, seed=seed)
    add_videos("gaze", ["video 1", "video 2"])
    run = make_all_run("lite on two", trained_on=TRAINED_ON, seed=5)
    report = scoring.build_report(trained_on=TRAINED_ON, study_ids=[], columns="sequences")
    assert report.activities == ["gaze / video 1", "gaze / video 2"]
    frames = {v: [f for f in frames_by_activity()["gaze"] if f.sequence.name == v] for v in ("video 1", "video 2")}
    prior = ActionObjectPrior().fit_masks([truth_mask(f) for a in TRAINED_ON for f in frames_by_activity()[a]])
    for video, fs in frames.items():
        masks = [truth_mask(f) for f in fs]
        assert_cell(row(report, f"egonet-lite (run {run.id})").cells[f"gaze / {video}"],
                    score_maps([stored_prediction(run, f) for f in fs], masks), 3)
        assert_cell(row(report, "AOP").cells[f"gaze / {video}"], score_maps([prior.predict(rgb_of(f)) for f in fs], masks), 3)
    data = json.loads(report.to_json())
    assert data["columns"] == "sequences" and "resampled within each column (recording)" in data["ci"]["method"]
    assert "The table's columns are the recordings (sequences) of the activities" in report.to_methods()
    with pytest.raises(scoring.ScoringProblem, match="columns must be one of activities, sequences") as err:
        scoring.build_report(columns="videos")
    assert err.value.field == "columns"


@pytest.mark.slow  # the worker fits the five learned baselines
def test_the_worker_fits_a_training_sets_baselines_when_the_page_would_wait(app, admin_client):
    app.config["BASELINE_INLINE_S"] = 0.0
    with app.app_context():
        for seed, name in enumerate(("cooking", "hotel", "desk work")):
            add_activity(name, seed=seed)
    url = "/scores/?trained_on=cooking&trained_on=hotel"
    page = admin_client.get(url).get_data(as_text=True)
    assert "being fitted per fold and scored by the worker" in page and 'data-row="baseline:aop"' not in page
    with app.app_context():
        (task,) = current_huey().pending()
        assert task.name.endswith("score_baselines") and task.args == (99, TRAINED_ON, "activities")
        current_huey().flush()
        score_baselines.func(*task.args)  # what the worker runs
    page = admin_client.get(url).get_data(as_text=True)
    assert 'data-row="baseline:aop"' in page and 'title="trained on: cooking, hotel"' in page
