"""The score table: people, baselines and model rows against a direct computation; cache; renderers; CLI; page."""

import csv
import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.extensions import db
from app.models import Annotation, Frame, Status
from app.models.studies import Participant, Study
from app.models.training import Checkpoint, FoldsMode, Prediction, RunStatus, TrainingRun
from app.services import ground_truth, media, scoring, studies, training
from app.services.demo import create_demo
from app.services.importing import FrameItem, add_frames
from app.services.scoring import sources as scoring_sources
from egonet import clicks as egonet_clicks
from egonet import io as egonet_io
from egonet.baselines import ActionObjectPrior, CenterPrior, GraphSaliency, HandledViewedObject, SpectralResidualSaliency
from egonet.metrics import score_maps
from tests.app.access.studies import build_study

SIZE = (48, 64)
HANDLED_ROW = "handled + viewed object (hands: labelled tactile objects)"
# Each activity's action-object sits somewhere else, so a prior fitted with
# or without the tested activity's own masks gives different scores.
BOXES = {"cooking": (slice(5, 20), slice(5, 25)), "hotel": (slice(25, 45), slice(35, 60)), "desk work": (slice(15, 35), slice(20, 45))}


def add_activity(name: str, *, n: int = 3, seed: int = 0) -> None:
    """``n`` labelled frames of random colour with the activity's box (shifted a little per frame) as ground truth."""
    rng = np.random.default_rng(seed)
    rows, cols = BOXES[name]

    def items():
        for i in range(n):
            mask = np.zeros(SIZE, bool)
            mask[rows.start + i : rows.stop, cols.start : cols.stop - i] = True
            rgb = rng.integers(0, 255, (*SIZE, 3), dtype=np.uint8)
            rgb[mask] //= 3  # a darker object, so saliency has something to find
            # Cooking's objects are handled (tactile), the others' only looked at.
            meta = {"kind": "tactile" if name == "cooking" else "visual"}
            yield FrameItem(f"{name}-{i}", i, f"test {name} {i}", rgb=rgb, mask=mask, meta=meta)

    add_frames(activity=name, sequence="take", items=items(), mask_status=Status.REVIEWED)


def frames_by_activity() -> dict[str, list[Frame]]:
    out: dict[str, list[Frame]] = {}
    for frame in ground_truth.labelled_frames():
        out.setdefault(frame.sequence.activity.name, []).append(frame)
    return out


def truth_mask(frame: Frame) -> np.ndarray:
    return ground_truth.mask_of(ground_truth.ground_truths([frame.id])[frame.id])


def rgb_of(frame: Frame) -> np.ndarray:
    return egonet_io.read_image(media.absolute_path(frame.rgb_path))


def row(report: scoring.Report, name: str) -> scoring.Row:
    return next(r for r in report.rows if r.name == name)


def answer(participant: Participant, answers) -> list[int]:
    """Consent, start, then give ``answers(trial)`` to trials in order until it returns None; return the answered frame ids."""
    studies.answer_consent(participant, agree=True)
    studies.start_session(participant)
    state = studies.session_state(participant)
    answered = []
    while state.trial is not None:
        given = answers(state.trial)
        if given is None:
            break
        answered.append(state.trial.frame.id)
        state = studies.submit(participant, state.trial, given)
    return answered


# --------------------------------------------------------------------------
# People


def test_people_rows_match_a_direct_computation_on_the_frames_they_answered(ctx, tmp_path):
    ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=2, sigma_px=6.0)
    first, second = (db.session.get(Participant, pid) for pid in ids["participants"])
    # P01 clicks every frame at a known point; P02 answers "none" once, clicks twice, then stops.
    clicks_of = {}

    def first_answers(trial):
        clicks_of[first.id, trial.frame.id] = [(17.0, 14.0)]
        return studies.Answer(clicks=[(17.0, 14.0, 400.0)])

    def second_answers(trial):
        if trial.position == 1:
            clicks_of[second.id, trial.frame.id] = []
            return studies.Answer(clicks=[], none=True)
        if trial.position <= 3:
            clicks_of[second.id, trial.frame.id] = [(40.0, 30.0), (10.0, 12.0)]
            return studies.Answer(clicks=[(40.0, 30.0, 300.0), (10.0, 12.0, 900.0)])
        return None

    answered = {first.id: answer(first, first_answers), second.id: answer(second, second_answers)}
    assert len(answered[first.id]) == 4 and len(answered[second.id]) == 3

    report = scoring.build_report(run_ids=[], study_ids=[ids["study"]], baselines=False)
    assert [(r.name, r.kind) for r in report.rows] == [("P01", "human"), ("P02", "human")]
    assert report.activities == ["cooking", "hotel"]

    study = db.session.get(Study, ids["study"])
    for person in (first, second):
        by_activity: dict[str, tuple[list, list]] = {}
        for frame_id in answered[person.id]:
            frame = db.session.get(Frame, frame_id)
            labels = studies.superpixel_labels(frame, study.superpixels)
            soft = egonet_clicks.soft_mask(SIZE, clicks_of[person.id, frame_id], sigma=6.0, labels=labels)
            probs, masks = by_activity.setdefault(frame.sequence.activity.name, ([], []))
            probs.append(soft)
            masks.append(truth_mask(frame))
        got = row(report, person.label)
        assert set(got.cells) == set(by_activity)
        expected = {a: score_maps(p, m) for a, (p, m) in by_activity.items()}
        for activity, score in expected.items():
            cell = got.cells[activity]
            assert cell.max_f == score.max_f and cell.ap is None  # MF only for people
            assert cell.n_frames == len(by_activity[activity][0])
        assert got.mean() == (pytest.approx(np.mean([s.max_f for s in expected.values()]), abs=1e-12), None)
        pooled = score_maps([p for ps, _ in by_activity.values() for p in ps], [m for _, ms in by_activity.values() for m in ms])
        assert got.overall.max_f == pooled.max_f
        assert got.overall.n_frames == len(answered[person.id])
    assert sum(c.n_frames for c in row(report, "P02").cells.values()) == 3  # only what P02 answered

    # Two studies: names say which study; a participant without answers is only a note.
    other = build_study(tmp_path / "other", activities=("desk work",), frames=2, per_activity=1, participants=1)
    both = scoring.build_report(run_ids=[], study_ids=[ids["study"], other["study"]], baselines=False)
    assert [r.name for r in both.rows] == [f"P01 (study {ids['study']})", f"P02 (study {ids['study']})"]
    assert any("no answered trials" in note for note in both.notes)


# --------------------------------------------------------------------------
# Baselines


def test_baselines_match_a_direct_computation_and_aop_follows_the_fold_rule(ctx):
    for seed, name in enumerate(BOXES):
        add_activity(name, seed=seed)
    report = scoring.build_report(run_ids=[], study_ids=[], baselines=True)
    assert [r.name for r in report.rows] == [
        "AOP", "centre prior", "saliency", "GBVS", "handled + viewed object (hands: labelled tactile objects)"
    ]
    assert report.activities == sorted(BOXES)

    frames = frames_by_activity()
    masks = {a: [truth_mask(f) for f in fs] for a, fs in frames.items()}
    rgbs = {a: [rgb_of(f) for f in fs] for a, fs in frames.items()}
    aop = row(report, "AOP")
    for activity in frames:
        # The fold's prior: the mean mask of the *other* activities' labelled frames.
        others = [m for a, ms in masks.items() if a != activity for m in ms]
        prior = ActionObjectPrior.fit(others)
        expected = score_maps([prior.predict(rgb) for rgb in rgbs[activity]], masks[activity])
        assert aop.cells[activity].max_f == pytest.approx(expected.max_f, abs=1e-9)
        assert aop.cells[activity].ap == pytest.approx(expected.ap, abs=1e-9)
        assert aop.cells[activity].n_frames == 3
        # A prior that has seen the tested activity scores differently: the fold rule matters here.
        leaky = ActionObjectPrior.fit([m for ms in masks.values() for m in ms])
        assert score_maps([leaky.predict(rgb) for rgb in rgbs[activity]], masks[activity]).ap != pytest.approx(expected.ap, abs=1e-3)

    def handled(rgb, mask, activity):  # the hands: the labelled tactile object (cooking's), else the centre
        return HandledViewedObject(width=160, scale=50.0, max_area=0.05).predict(rgb, near=mask if activity == "cooking" else None)

    predictors = (("centre prior", lambda rgb, m, a: CenterPrior().predict(rgb)),
                  ("saliency", lambda rgb, m, a: SpectralResidualSaliency().predict(rgb)),
                  ("GBVS", lambda rgb, m, a: GraphSaliency().predict(rgb)),
                  ("handled + viewed object (hands: labelled tactile objects)", handled))
    for name, predict in predictors:
        got = row(report, name)
        for activity in frames:
            expected = score_maps([predict(rgb, m, activity) for rgb, m in zip(rgbs[activity], masks[activity])], masks[activity])
            assert (got.cells[activity].max_f, got.cells[activity].ap) == (expected.max_f, expected.ap)
        pooled = score_maps(
            [predict(rgb, m, a) for a in frames for rgb, m in zip(rgbs[a], masks[a])], [m for a in frames for m in masks[a]]
        )
        assert (got.overall.max_f, got.overall.ap) == (pooled.max_f, pooled.ap)
        mean_mf, mean_ap = got.mean()
        assert mean_mf == pytest.approx(np.mean([got.cells[a].max_f for a in frames]))
        assert mean_ap == pytest.approx(np.mean([got.cells[a].ap for a in frames]))


def test_with_one_activity_there_is_no_aop(ctx):
    add_activity("cooking")
    report = scoring.build_report(run_ids=[], study_ids=[])
    assert [r.name for r in report.rows] == ["centre prior", "saliency", "GBVS", "handled + viewed object (hands: labelled tactile objects)"]
    assert report.notes == ["AOP: no other activity has labelled frames to fit the prior for cooking."]


def test_per_image_mode_and_thresholds(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    pooled = scoring.build_report(run_ids=[], study_ids=[])
    per_image = scoring.build_report(run_ids=[], study_ids=[], per_image=True)
    coarse = scoring.build_report(run_ids=[], study_ids=[], thresholds=9)
    frames = frames_by_activity()["hotel"]
    probs = [CenterPrior().predict(rgb_of(f), None) for f in frames]
    masks = [truth_mask(f) for f in frames]
    assert row(per_image, "centre prior").cells["hotel"].max_f == score_maps(probs, masks, per_image=True).max_f
    assert row(coarse, "centre prior").cells["hotel"].ap == score_maps(probs, masks, thresholds=9).ap
    assert row(pooled, "centre prior").cells["hotel"].max_f == score_maps(probs, masks).max_f
    assert len(row(coarse, "AOP").curves["hotel"].precision) == 9
    with pytest.raises(scoring.ScoringProblem) as info:
        scoring.build_report(thresholds=0)
    assert info.value.field == "thresholds"


# --------------------------------------------------------------------------
# Model rows (held-out predictions of completed training runs)


def make_run(run_id_hint: str, *, held_out: list[str], folds: str = "loao", seed: int = 0) -> TrainingRun:
    """A done run of egonet-lite with a stored 16-bit prediction for every frame of ``held_out`` activities.

    Every other labelled frame gets a prediction too, but not held out:
    scoring must ignore it.
    """
    rng = np.random.default_rng(seed)
    run = TrainingRun(
        name=run_id_hint, model_name="egonet-lite", folds=FoldsMode(folds), epochs=1, device="cpu", seed=seed, status=RunStatus.DONE
    )
    db.session.add(run)
    db.session.flush()
    checkpoint = Checkpoint(run_id=run.id, fold="fold", path=f"run-{run.id}/fold.pt", epochs=1)
    db.session.add(checkpoint)
    db.session.flush()
    for activity, frames in frames_by_activity().items():
        for frame in frames:
            u16 = rng.integers(0, 65536, (frame.height, frame.width), dtype=np.uint16)
            path = media.store(egonet_io.encode_png(u16), ".png")
            db.session.add(Prediction(run_id=run.id, checkpoint_id=checkpoint.id, frame_id=frame.id, path=path, held_out=activity in held_out))
    db.session.commit()
    return run


def stored_prediction(run: TrainingRun, frame: Frame) -> np.ndarray:
    """The map as stored (what the run predicted, to 16 bits), read straight from its PNG."""
    path = db.session.execute(db.select(Prediction.path).filter_by(run_id=run.id, frame_id=frame.id)).scalar_one()
    return cv2.imread(str(media.absolute_path(path)), cv2.IMREAD_UNCHANGED).astype(np.float32) / 65535.0


def test_model_rows_score_held_out_predictions_only(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    loao = make_run("lite loao", held_out=["cooking", "hotel"], seed=3)
    single = make_run("lite single", held_out=["hotel"], folds="single", seed=4)
    report = scoring.build_report(study_ids=[], baselines=False)
    # Newest first, named by model and run.
    assert [(r.name, r.kind) for r in report.rows] == [
        (f"egonet-lite (run {single.id})", "model"),
        (f"egonet-lite (run {loao.id})", "model"),
    ]
    assert row(report, f"egonet-lite (run {single.id})").detail == "lite single, single folds"
    frames = frames_by_activity()
    for run, activities in ((loao, ["cooking", "hotel"]), (single, ["hotel"])):
        got = row(report, f"egonet-lite (run {run.id})")
        assert sorted(got.cells) == activities  # cooking's predictions of the single run are not held out
        for activity in activities:
            probs = [stored_prediction(run, f) for f in frames[activity]]
            expected = score_maps(probs, [truth_mask(f) for f in frames[activity]])
            assert (got.cells[activity].max_f, got.cells[activity].ap) == (expected.max_f, expected.ap)
            assert got.cells[activity].n_frames == 3
    assert report.partial_means()  # the single run has hotel only
    assert "*" in report.to_table() and "$^*$" in report.to_latex()

    one = scoring.build_report(run_ids=[loao.id], study_ids=[], baselines=False)
    assert [r.name for r in one.rows] == [f"egonet-lite (run {loao.id})"]
    unfinished = TrainingRun(name="x", model_name="egonet-lite", folds=FoldsMode.LOAO, epochs=1, device="cpu", seed=0, status=RunStatus.RUNNING)
    db.session.add(unfinished)
    db.session.commit()
    for run_id in (unfinished.id, 999):
        with pytest.raises(scoring.ScoringProblem) as info:
            scoring.build_report(run_ids=[run_id])
        assert info.value.field == "runs" and f"run {run_id} is not a completed training run" in str(info.value)


def test_model_frames_without_ground_truth_are_left_out_with_a_note(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    run = make_run("lite", held_out=["hotel"])
    frame = frames_by_activity()["hotel"][0]
    # The frame's ground truth went back to work after the run was trained on it.
    annotation = db.session.execute(db.select(Annotation).filter_by(frame_id=frame.id)).scalar_one()
    annotation.status = Status.IN_PROGRESS
    db.session.commit()
    report = scoring.build_report(run_ids=[run.id], study_ids=[], baselines=False)
    assert row(report, f"egonet-lite (run {run.id})").cells["hotel"].n_frames == 2
    assert f"run {run.id}: 1 held-out frames no longer have a ground truth and were left out." in report.notes


def test_a_run_whose_maps_cannot_be_scored_is_a_note_not_an_error(ctx, app):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    run = make_run("lite", held_out=["cooking"])
    prediction = db.session.execute(db.select(Prediction).filter_by(run_id=run.id, held_out=True)).scalars().first()
    prediction.path = media.store(egonet_io.encode_png(np.zeros((10, 10), np.uint16)), ".png")  # not the frame's size
    db.session.commit()
    report = scoring.build_report(study_ids=[])
    assert [r.name for r in report.rows] == ["AOP", "centre prior", "saliency", "GBVS", HANDLED_ROW]
    assert any(note.startswith(f"egonet-lite (run {run.id}) could not be scored:") and "10x10" in note for note in report.notes)
    assert len(list((Path(app.config["CACHE_ROOT"]) / "scores").glob("*.json"))) == 1  # the baselines only


@pytest.mark.slow
def test_a_small_trained_run_scores_as_a_direct_computation_on_its_held_out_maps(app, runner, tmp_path):
    import torch

    app.config["CHECKPOINT_ROOT"] = str(tmp_path / "checkpoints")
    with app.app_context():
        create_demo(frames_per_activity=5, unlabelled_fraction=0, width=64, height=48)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a tiny model trains faster so on a shared machine
    try:
        args = ["egonet", "train", "--model", "egonet-lite", "--folds", "single", "--epochs", "1", "--size", "64x48",
                "--batch-size", "2", "--device", "cpu", "--activities", "cooking", "--activities", "dining"]  # fmt: skip
        result = runner.invoke(args=args)
    finally:
        torch.set_num_threads(threads)
    assert result.exit_code == 0, result.output

    result = runner.invoke(args=["egonet", "score", "--format", "json", "--no-baselines", "--studies", ""])
    assert result.exit_code == 0, result.output
    (got,) = json.loads(result.stdout)["rows"]
    with app.app_context():
        (run,) = training.completed_runs()
        assert got["name"] == f"egonet-lite (run {run.id})" and got["kind"] == "model"
        by_activity: dict[str, tuple[list, list]] = {}
        for frame, probability in training.held_out_predictions(run):
            probs, masks = by_activity.setdefault(frame.sequence.activity.name, ([], []))
            probs.append(probability)
            masks.append(truth_mask(frame))
    assert sorted(by_activity) == ["cooking", "dining"]
    for activity, (probs, masks) in by_activity.items():
        expected = score_maps(probs, masks)
        assert got["cells"][activity] == {"max_f": expected.max_f, "ap": expected.ap, "n_frames": len(probs)}
    assert got["mean"]["max_f"] == pytest.approx(np.mean([c["max_f"] for c in got["cells"].values()]))


# --------------------------------------------------------------------------
# Cache


def test_statistics_are_cached_and_recomputed_when_their_inputs_change(ctx, monkeypatch):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    run = make_run("lite", held_out=["cooking", "hotel"])
    first = scoring.build_report(study_ids=[])
    scored = []
    run_stats, baseline_stats = scoring_sources.run_stats, scoring_sources.baseline_stats
    monkeypatch.setattr(scoring_sources, "run_stats", lambda *a: scored.append("run") or run_stats(*a))
    monkeypatch.setattr(scoring_sources, "baseline_stats", lambda *a: scored.append("baselines") or baseline_stats(*a))

    again = scoring.build_report(study_ids=[])
    assert scored == []  # read back
    assert again.to_json() == first.to_json()
    per_image = scoring.build_report(study_ids=[], per_image=True)  # the same statistics serve per-image mode
    assert per_image.per_image and scored == []
    assert row(per_image, "centre prior").cells["cooking"].max_f != row(first, "centre prior").cells["cooking"].max_f
    assert scoring.build_report(study_ids=[], use_cache=False).to_json() == first.to_json()
    assert scored == ["run", "baselines"]

    # The run's held-out maps are predicted again: only the run is scored again.
    scored.clear()
    old = db.session.execute(db.select(Prediction).filter_by(run_id=run.id)).scalars().first()
    again = Prediction(run_id=run.id, checkpoint_id=old.checkpoint_id, frame_id=old.frame_id, path=old.path, held_out=True)
    db.session.delete(old)
    db.session.flush()
    db.session.add(again)
    db.session.commit()
    scoring.build_report(study_ids=[])
    assert scored == ["run"]

    # Someone edits a ground truth: everything that depends on it is scored again.
    scored.clear()
    annotation = db.session.execute(db.select(Annotation)).scalars().first()
    annotation.review_comment = "checked again"
    db.session.commit()
    fresh = scoring.build_report(study_ids=[])
    assert scored == ["run", "baselines"]
    assert fresh.to_json() == first.to_json()  # the masks and maps themselves did not change


def test_unreadable_cache_is_scored_again(ctx, app):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    first = scoring.build_report(run_ids=[], study_ids=[])
    files = list((Path(app.config["CACHE_ROOT"]) / "scores").glob("*.json"))
    assert len(files) == 1
    files[0].write_text("{not json")
    assert scoring.build_report(run_ids=[], study_ids=[]).to_csv() == first.to_csv()
    assert json.loads(files[0].read_text())["stats"]


# --------------------------------------------------------------------------
# Renderers


def cell(mf, ap, n=10):
    return scoring.Cell(mf, ap, n)


def curve():
    return scoring.Curve((1.0, 0.5), (0.2, 0.1), 0)


def hand_report() -> scoring.Report:
    def make(key, name, kind, cells):
        overall = cell(0.5, None if kind == "human" else 0.4, 20)
        return scoring.Row(key, name, kind, "", cells, overall, {**{a: curve() for a in cells}, scoring.ALL: curve()})

    rows = [
        make("run:1", "lite_v2 (run 1)", "model", {"cooking": cell(0.40, 0.30), "hotel": cell(0.20, 0.10)}),
        make("baseline:aop", "AOP", "baseline", {"cooking": cell(0.30, 0.35), "hotel": cell(0.20, 0.05)}),
        make("participant:1", "P01", "human", {"cooking": cell(0.45, None)}),
    ]
    return scoring.Report(activities=["cooking", "hotel"], rows=rows, notes=["a note"])


def test_mean_and_best_values():
    report = hand_report()
    assert report.rows[0].mean() == (pytest.approx(0.30), pytest.approx(0.20))
    assert report.rows[2].mean() == (0.45, None)
    best = report.best()
    assert best[("cooking", "mf")] == 0.45 and best[("cooking", "ap")] == 0.35
    assert best[("hotel", "mf")] == 0.20  # a tie: both rows are best
    assert best[("mean", "mf")] == 0.45 and best[("mean", "ap")] == 0.2
    assert not report.complete(report.rows[2]) and report.partial_means()


def test_latex_is_table_2_shaped_with_the_best_in_bold():
    tex = hand_report().to_latex()
    assert "\\begin{tabular}{lcccccc}" in tex and "\\bottomrule" in tex
    assert "\\multicolumn{2}{c}{cooking} & \\multicolumn{2}{c}{hotel} & \\multicolumn{2}{c}{mean}" in tex
    lines = {line.split(" & ")[0]: line for line in tex.splitlines() if " & " in line}
    assert lines["lite\\_v2 (run 1)"] == (
        "lite\\_v2 (run 1) & 0.400 & 0.300 & \\textbf{0.200} & \\textbf{0.100} & 0.300 & \\textbf{0.200} \\\\"
    )
    assert lines["AOP"] == "AOP & 0.300 & \\textbf{0.350} & \\textbf{0.200} & 0.050 & 0.250 & \\textbf{0.200} \\\\"
    assert lines["P01"] == "P01 & \\textbf{0.450} & -- & -- & -- & \\textbf{0.450}$^*$ & -- \\\\"
    assert tex.count("\\midrule") == 3  # one per group


def test_csv_table_and_json():
    report = hand_report()
    rows = list(csv.reader(io.StringIO(report.to_csv())))
    assert rows[0] == [
        "method", "kind", "cooking MF", "cooking AP", "cooking frames", "hotel MF", "hotel AP", "hotel frames",
        "mean MF", "mean AP", "mean over activities",
    ]  # fmt: skip
    assert rows[1] == ["lite_v2 (run 1)", "model", "0.4000", "0.3000", "10", "0.2000", "0.1000", "10", "0.3000", "0.2000", "2"]
    assert rows[3] == ["P01", "human", "0.4500", "", "10", "", "", "", "0.4500", "", "1"]

    table = report.to_table()
    assert "cooking" in table.splitlines()[0] and "mean" in table.splitlines()[0]
    line = next(line for line in table.splitlines() if line.startswith("lite_v2"))
    assert line.split() == ["lite_v2", "(run", "1)", "0.400", "0.300", "0.200", "0.100", "0.300", "0.200"]
    assert "-- People (MF only)" in table and "a note" in table and "* mean over" in table

    data = json.loads(report.to_json())
    assert data["activities"] == ["cooking", "hotel"] and data["thresholds"] == 99
    assert len(data["threshold_values"]) == 99 and data["threshold_values"][0] == 0.01
    first = data["rows"][0]
    assert first["cells"]["cooking"] == {"max_f": 0.4, "ap": 0.3, "n_frames": 10}
    assert first["mean"]["activities"] == 2 and first["curves"]["all"]["precision"] == [1.0, 0.5]
    assert "unweighted mean" in data["definition"]


def test_empty_report_renders():
    empty = scoring.Report(activities=[], rows=[])
    assert "nothing to score" in empty.to_table()
    assert list(csv.reader(io.StringIO(empty.to_csv()))) == [["method", "kind", "mean MF", "mean AP", "mean over activities"]]
    assert "\\begin{tabular}{lcc}" in empty.to_latex()
    assert json.loads(empty.to_json())["rows"] == []


def test_pr_plot_maps_curves_to_svg_coordinates():
    report = hand_report()
    plot = scoring.pr_plot(report, "cooking", width=300, height=270)
    left, top, right, bottom = scoring.PLOT_MARGIN
    assert [line.name for line in plot.lines] == ["lite_v2 (run 1)", "AOP", "P01"]
    first = plot.lines[0]
    # (recall 0.2, precision 1.0) then (0.1, 0.5)
    sx, sy = 300 - left - right, 270 - top - bottom
    assert first.points == f"{round(left + 0.2 * sx, 1)},{float(top)} {round(left + 0.1 * sx, 1)},{round(top + 0.5 * sy, 1)}"
    assert (first.best_x, first.best_y) == (round(left + 0.2 * sx, 1), float(top))
    assert plot.lines[2].dashed and not first.dashed
    assert "MF 0.400" in first.best_label
    assert len(plot.iso_f) == 4 and plot.title == "cooking"
    assert [line.name for line in scoring.pr_plot(report, "hotel").lines] == ["lite_v2 (run 1)", "AOP"]
    assert scoring.pr_plot(report, scoring.ALL).title == "All activities (pooled)"


# --------------------------------------------------------------------------
# CLI


def test_score_command_prints_each_format(ctx, runner, tmp_path):
    ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=1)
    answer(db.session.get(Participant, ids["participants"][0]), lambda t: studies.Answer(clicks=[(20.0, 15.0, 300.0)]))

    result = runner.invoke(args=["egonet", "score"])
    assert result.exit_code == 0, result.output
    table = result.stdout
    assert "AOP" in table and "centre prior" in table and "saliency" in table and "P01" in table
    assert "cooking" in table and "mean" in table

    result = runner.invoke(args=["egonet", "score", "--format", "csv", "--runs", "", "--studies", str(ids["study"])])
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(io.StringIO(result.stdout)))  # stdout holds the CSV only
    assert [r[0] for r in rows[1:]] == ["AOP", "centre prior", "saliency", "GBVS", HANDLED_ROW, "P01"]

    result = runner.invoke(args=["egonet", "score", "--format", "latex", "--no-baselines"])
    assert result.exit_code == 0 and "\\begin{tabular}" in result.stdout and "AOP" not in result.stdout

    result = runner.invoke(args=["egonet", "score", "--format", "json", "--studies", "", "--thresholds", "19", "--per-image", "--no-cache"])
    data = json.loads(result.stdout)
    assert data["thresholds"] == 19 and data["per_image"] is True
    assert [r["name"] for r in data["rows"]] == ["AOP", "centre prior", "saliency", "GBVS", HANDLED_ROW]

    report = scoring.build_report(run_ids=[], study_ids=[ids["study"]])
    assert runner.invoke(args=["egonet", "score", "--format", "csv"]).stdout == report.to_csv()


def test_score_command_errors_are_one_line(ctx, runner):
    result = runner.invoke(args=["egonet", "score", "--studies", "12"])
    assert result.exit_code == 1
    assert [line for line in result.output.splitlines() if line.startswith("Error:")] == ["Error: study 12 does not exist"]
    result = runner.invoke(args=["egonet", "score", "--runs", "x"])
    assert result.exit_code == 2 and "--runs" in result.output
    result = runner.invoke(args=["egonet", "score", "--format", "xml"])
    assert result.exit_code == 2 and "--format" in result.output
    result = runner.invoke(args=["egonet", "score", "--thresholds", "0"])
    assert result.exit_code == 2 and "--thresholds" in result.output


# --------------------------------------------------------------------------
# The page


def test_scores_page_shows_the_table_plots_and_downloads(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=1)
        answer(db.session.get(Participant, ids["participants"][0]), lambda t: studies.Answer(clicks=[(20.0, 15.0, 300.0)]))
        run_id = make_run("lite", held_out=["cooking"]).id
    page = admin_client.get("/scores/")
    assert page.status_code == 200
    html = page.get_data(as_text=True)
    assert 'id="score-table"' in html and "<svg" in html and "<polyline" in html
    for name in (f"egonet-lite (run {run_id})", "AOP", "centre prior", "saliency", "P01"):
        assert name in html
    assert html.count('class="pr-plot"') == 3  # all activities, cooking, hotel
    assert f'name="studies" value="{ids["study"]}" checked' in html
    assert f'name="runs" value="{run_id}" checked' in html
    assert f"/scores/table.csv?chosen=1&amp;runs={run_id}&amp;studies={ids['study']}&amp;baselines=1" in html

    page = admin_client.get("/scores/?chosen=1")  # nothing ticked: no rows
    assert page.status_code == 200 and "Nothing to score yet" in page.get_data(as_text=True)
    page = admin_client.get(f"/scores/?chosen=1&studies={ids['study']}")
    html = page.get_data(as_text=True)
    assert 'data-row="participant:' in html and 'data-row="baseline:aop"' not in html

    with admin_client.get(f"/scores/table.csv?chosen=1&baselines=1&studies={ids['study']}") as response:
        assert response.status_code == 200 and response.mimetype == "text/csv"
        assert 'filename="scores.csv"' in response.headers["Content-Disposition"]
        assert [r[0] for r in csv.reader(io.StringIO(response.get_data(as_text=True)))][1:] == ["AOP", "centre prior", "saliency", "GBVS", HANDLED_ROW, "P01"]
    with admin_client.get("/scores/table.tex") as response:
        assert response.status_code == 200 and "\\begin{tabular}" in response.get_data(as_text=True)
    with admin_client.get("/scores/table.json") as response:
        assert response.status_code == 200 and json.loads(response.get_data(as_text=True))["rows"]


def test_scores_page_refuses_bad_choices(admin_client):
    page = admin_client.get("/scores/?chosen=1&studies=99")
    assert page.status_code == 400 and "study 99 does not exist" in page.get_data(as_text=True)
    with admin_client.get("/scores/table.csv?chosen=1&runs=abc", headers={"Accept": "application/json"}) as response:
        assert response.status_code == 400 and response.get_json()["fields"] == {"runs": "must be whole numbers"}
    with admin_client.get("/scores/table.json?chosen=1&runs=5", headers={"Accept": "application/json"}) as response:
        assert response.status_code == 400 and "runs" in response.get_json()["fields"]
    assert admin_client.get("/scores/table.xml").status_code == 404
