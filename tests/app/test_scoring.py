"""The score table's numbers: people, baselines, models and seed groups against direct computations; frames; comparisons; cache.

The renderers, the CLI and the page are in tests/app/test_scoring_pages.py.
"""

import json
from datetime import UTC, datetime, timedelta
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
from app.services.scoring import cache as scoring_cache
from app.services.scoring import sources as scoring_sources
from egonet import clicks as egonet_clicks
from egonet import io as egonet_io
from egonet.baselines import (
    BASELINES,
    ActionObjectPrior,
    CenterPrior,
    GraphSaliency,
    HandledViewedObj,
    SpectralResidualSaliency,
    TrainingFrame,
)
from egonet.metrics import MIN_FRAMES, count_stats, score_maps
from tests.app.access.studies import build_study

SIZE = (48, 64)
HANDLED_ROW = "Handled+Viewed-Obj (hands: skin colour)"  # these frames have no hand instances
# The paper's Table 2 order, then the references.
BASELINE_ROWS = ["Judd", "GBVS", HANDLED_ROW, "AOP", "FP-MCG", "salObj+depth", "centre prior", "saliency"]
# Each activity's action-object sits somewhere else, so a prior fitted with
# or without the tested activity's own masks gives different scores.
BOXES = {"cooking": (slice(5, 20), slice(5, 25)), "hotel": (slice(25, 45), slice(35, 60)), "desk work": (slice(15, 35), slice(20, 45))}
T0 = datetime(2026, 5, 4, 10, 0, 0, tzinfo=UTC)


class Clock:
    """The studies' clock (the app's STUDY_CLOCK), moved by hand."""

    def __init__(self, t: datetime):
        self.t = t

    def __call__(self) -> datetime:
        return self.t


def add_activity(name: str, *, n: int = 3, seed: int = 0, hands: bool = False) -> None:
    """``n`` labelled frames of random colour with the activity's box (shifted a little per frame) as ground truth.

    With ``hands``, each frame also shows a skin-coloured hand at the bottom, stored as an instance labelled ``hand``.
    """
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
            hand = None
            if hands:
                hand = np.zeros(SIZE, bool)
                hand[38:, 4 + 6 * i : 20 + 6 * i] = True
                rgb[hand] = (205, 145, 115)
            yield FrameItem(f"{name}-{i}", i, f"test {name} {i}", rgb=rgb, mask=mask, meta=meta, hands=hand)

    add_frames(activity=name, sequence="take", items=items(), mask_status=Status.REVIEWED)


def frames_by_activity() -> dict[str, list[Frame]]:
    out: dict[str, list[Frame]] = {}
    for frame in ground_truth.labelled_frames():
        out.setdefault(frame.sequence.activity.name, []).append(frame)
    return out


def truth_mask(frame: Frame) -> np.ndarray:
    return ground_truth.mask_of(ground_truth.ground_truths([frame.id])[frame.id])


def rgb_of(frame: Frame) -> np.ndarray:
    return egonet_io.read_image(media.local_path(frame.rgb_path))


def row(report: scoring.Report, name: str) -> scoring.Row:
    return next(r for r in report.all_rows() if r.name == name)


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


def assert_cell(cell: scoring.Cell, expected, n: int, *, ap: bool = True) -> None:
    """A cell equals a direct ``score_maps`` (to 1e-12), has ``n`` frames, and an interval around its value (none below MIN_FRAMES)."""
    assert cell.n_frames == n
    assert cell.max_f == pytest.approx(expected.max_f, abs=1e-12)
    if n < MIN_FRAMES:
        assert cell.too_few and cell.ci["max_f"] is None
    else:
        lo, hi = cell.ci["max_f"]
        assert not cell.too_few and lo <= cell.max_f + 1e-12 and cell.max_f - 1e-12 <= hi
    if ap:
        assert cell.ap == pytest.approx(expected.ap, abs=1e-12)
    else:
        assert cell.ap is None and cell.ci["ap"] is None  # MF only for people


# --------------------------------------------------------------------------
# People: shared frames, each row's own frames, unanswered trials


def test_people_on_shared_and_own_frames_and_their_unanswered_trials(app, ctx, tmp_path):
    clock = app.config["STUDY_CLOCK"] = Clock(T0)
    ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=3, per_activity=2, participants=2, sigma_px=6.0)
    first, second = (db.session.get(Participant, pid) for pid in ids["participants"])
    clicks_of = {}

    def first_answers(trial):
        clicks_of[first.id, trial.frame.id] = [(17.0, 14.0)]
        return studies.Answer(clicks=[(17.0, 14.0, 400.0)])

    def second_answers(trial):  # "none" once, clicks twice, then the tab is closed
        if trial.position == 1:
            clicks_of[second.id, trial.frame.id] = []
            return studies.Answer(clicks=[], none=True)
        if trial.position <= 3:
            clicks_of[second.id, trial.frame.id] = [(40.0, 30.0), (10.0, 12.0)]
            return studies.Answer(clicks=[(40.0, 30.0, 300.0), (10.0, 12.0, 900.0)])
        return None

    answered = {first.id: answer(first, first_answers), second.id: answer(second, second_answers)}
    assert len(answered[first.id]) == 4 and len(answered[second.id]) == 3
    study = db.session.get(Study, ids["study"])
    frames = {fid: db.session.get(Frame, fid) for fid in answered[first.id]}
    activity = {fid: f.sequence.activity.name for fid, f in frames.items()}

    def soft(person, fid):
        if (person.id, fid) not in clicks_of:
            return np.zeros(SIZE, np.float32)  # no answer: an empty map
        labels = studies.superpixel_labels(frames[fid], study.superpixels)
        return egonet_clicks.soft_mask(SIZE, clicks_of[person.id, fid], sigma=6.0, labels=labels)

    def direct(person, fids):
        by_activity = {}
        for fid in fids:
            probs, masks = by_activity.setdefault(activity[fid], ([], []))
            probs.append(soft(person, fid))
            masks.append(truth_mask(frames[fid]))
        return {a: (score_maps(p, m), len(p)) for a, (p, m) in by_activity.items()}

    def check(report, person, fids):
        got = row(report, person.label)
        expected = direct(person, fids)
        assert set(got.cells) == set(expected)
        for a, (score, n) in expected.items():
            assert_cell(got.cells[a], score, n, ap=False)
        assert got.mean.max_f == pytest.approx(np.mean([s.max_f for s, _ in expected.values()]), abs=1e-12)
        assert got.mean.n_frames == len(fids) and got.mean.activities == len(expected)

    # P02 is still in session: their last trial is pending, not unanswered.
    each = scoring.build_report(run_ids=[], study_ids=[ids["study"]], baselines=False, frames="each")
    assert [(r.name, r.kind, r.unanswered) for r in each.rows] == [("P01", "human", 0), ("P02", "human", 0)]
    check(each, first, answered[first.id])
    check(each, second, answered[second.id])
    assert "P02 is still in session: trials not answered yet (1) are left out." in each.notes
    # The activity where P02 has one frame less: the two are on different frames, so neither is bold there.
    short = activity[next(f for f in answered[first.id] if f not in answered[second.id])]
    best = each.best()
    assert not best.get((short, "max_f")) and not best.get(("mean", "max_f"))
    full = next(a for a in each.activities if a != short)
    assert set(best[full, "max_f"]) <= {r.key for r in each.rows} and best[full, "max_f"]

    # By default both are scored on the frames both have.
    shared = scoring.build_report(run_ids=[], study_ids=[ids["study"]], baselines=False)
    assert shared.provenance.frames == "shared"
    check(shared, first, answered[second.id])
    check(shared, second, answered[second.id])
    assert shared.row(f"participant:{first.id}").cells[short].frames_available == 2
    assert any(note.startswith(f"{short}: 1 frame shared by the 2 rows") for note in shared.notes)

    # The session's time runs out: the trial P02 never answered counts as an empty map.
    clock.t = T0 + timedelta(hours=2)
    late = scoring.build_report(run_ids=[], study_ids=[ids["study"]], baselines=False)
    assert [(r.name, r.unanswered) for r in late.rows] == [("P01", 0), ("P02", 1)]
    check(late, first, answered[first.id])
    check(late, second, answered[first.id])  # the empty map included
    assert not any("still in session" in note for note in late.notes)
    # Answered trials only, as before: P02 back on 3 frames, and the table still says 1 was unanswered.
    answered_only = scoring.build_report(run_ids=[], study_ids=[ids["study"]], baselines=False, answered_only=True, frames="each")
    check(answered_only, second, answered[second.id])
    assert row(answered_only, "P02").unanswered == 1 and answered_only.provenance.answered_only

    # Two studies: names say which study; a participant who has not started is only a note.
    other = build_study(tmp_path / "other", activities=("desk work",), frames=2, per_activity=1, participants=1)
    both = scoring.build_report(run_ids=[], study_ids=[ids["study"], other["study"]], baselines=False)
    assert [r.name for r in both.rows] == [f"P01 (study {ids['study']})", f"P02 (study {ids['study']})"]
    assert f"P01 (study {other['study']}) has not started." in both.notes


def test_an_expired_trial_is_unanswered_while_the_session_goes_on(app, ctx, tmp_path):
    clock = app.config["STUDY_CLOCK"] = Clock(T0)
    ids = build_study(tmp_path, activities=("cooking", "hotel"), frames=2, per_activity=2, participants=1, trial_limit_s=5)
    person = db.session.get(Participant, ids["participants"][0])
    studies.answer_consent(person, agree=True)
    studies.start_session(person)
    state = studies.session_state(person)
    state = studies.submit(person, state.trial, studies.Answer(clicks=[(20.0, 15.0, 300.0)]))
    expired = state.trial.frame.id
    clock.t += timedelta(seconds=10)  # the second trial's 5 s run out
    state = studies.session_state(person)
    studies.submit(person, state.trial, studies.Answer(clicks=[(20.0, 15.0, 300.0)]))
    report = scoring.build_report(run_ids=[], study_ids=[ids["study"]], baselines=False, frames="each")
    (got,) = report.rows
    assert got.unanswered == 1 and got.mean.n_frames == 3  # two answers and the expired trial; the fourth is pending
    # Per image, it is there as an empty map (best F 0), marked unanswered.
    frame = db.session.get(Frame, expired)
    table = scoring.frame_table(run_ids=[], study_ids=[ids["study"]], baselines=False, activity=frame.sequence.activity.name, frames="each")
    line = next(line for line in table.lines if line.frame_id == expired)
    assert line.scores[got.key][0] == 0.0 and line.scores[got.key][2] is None and line.answered == {got.key: False}
    only = scoring.build_report(run_ids=[], study_ids=[ids["study"]], baselines=False, frames="each", answered_only=True)
    assert only.rows[0].mean.n_frames == 2 and only.rows[0].unanswered == 1


# --------------------------------------------------------------------------
# Baselines, and the three conventions


@pytest.mark.one_database
def test_baselines_match_a_direct_computation_and_aop_follows_the_fold_rule(ctx):
    for seed, name in enumerate(BOXES):
        add_activity(name, seed=seed)
    report = scoring.build_report(run_ids=[], study_ids=[], baselines=True)
    assert [r.name for r in report.rows] == BASELINE_ROWS
    learned = {r.name for r in report.rows if r.detail == "fitted per fold under leave-one-activity-out"}
    assert learned == {"Judd", HANDLED_ROW, "AOP", "FP-MCG", "salObj+depth"}
    assert report.activities == sorted(BOXES)

    frames = frames_by_activity()
    masks = {a: [truth_mask(f) for f in fs] for a, fs in frames.items()}
    rgbs = {a: [rgb_of(f) for f in fs] for a, fs in frames.items()}
    training = {a: [TrainingFrame(rgb, None, m) for rgb, m in zip(rgbs[a], masks[a])] for a in frames}
    for key in ("judd", "aop", "fpmcg", "salobj"):
        got = row(report, BASELINES[key].name)
        for activity in frames:
            # The fold's model: fitted on the *other* activities' labelled frames only.
            model = BASELINES[key]().fit([f for a, fs in training.items() if a != activity for f in fs])
            expected = score_maps([model.predict(rgb) for rgb in rgbs[activity]], masks[activity])
            assert_cell(got.cells[activity], expected, 3)
    for activity in frames:
        # A prior that has seen the tested activity scores differently: the fold rule matters here.
        expected = row(report, "AOP").cells[activity]
        leaky = ActionObjectPrior().fit_masks([m for ms in masks.values() for m in ms])
        assert score_maps([leaky.predict(rgb) for rgb in rgbs[activity]], masks[activity]).ap != pytest.approx(expected.ap, abs=1e-3)

    def handled(rgb, mask, activity):  # no hand labels anywhere: every fold's hands are skin colour, never the labels
        return HandledViewedObj().fit_summaries([]).predict(rgb)

    predictors = (("centre prior", lambda rgb, m, a: CenterPrior().predict(rgb)),
                  ("saliency", lambda rgb, m, a: SpectralResidualSaliency().predict(rgb)),
                  ("GBVS", lambda rgb, m, a: GraphSaliency().predict(rgb)),
                  (HANDLED_ROW, handled))
    for name, predict in predictors:
        got = row(report, name)
        for activity in frames:
            expected = score_maps([predict(rgb, m, activity) for rgb, m in zip(rgbs[activity], masks[activity])], masks[activity])
            assert (got.cells[activity].max_f, got.cells[activity].ap) == (expected.max_f, expected.ap)  # the same arithmetic
        pooled = score_maps(
            [predict(rgb, m, a) for a in frames for rgb, m in zip(rgbs[a], masks[a])], [m for a in frames for m in masks[a]]
        )
        assert got.overall.max_f == pytest.approx(pooled.max_f, abs=1e-12) and got.overall.n_frames == 9
        assert got.mean.max_f == pytest.approx(np.mean([got.cells[a].max_f for a in frames]), abs=1e-12)
        assert got.mean.ap == pytest.approx(np.mean([got.cells[a].ap for a in frames]), abs=1e-12)
        # 3 frames in each activity: the mean over them is n too small too (every activity is resampled on its own).
        assert got.mean.too_few and got.overall.too_few and got.mean.ci["max_f"] is None


def test_with_one_activity_there_are_no_learned_baselines(ctx):
    add_activity("cooking")
    report = scoring.build_report(run_ids=[], study_ids=[])
    learned = ("Judd", "Handled+Viewed-Obj", "AOP", "FP-MCG", "salObj+depth")  # the registry's order
    assert [r.name for r in report.rows] == [name for name in BASELINE_ROWS if name not in (*learned, HANDLED_ROW)]
    assert report.notes == [f"{name}: no other activity has labelled frames to fit the fold of cooking." for name in learned]


@pytest.mark.one_database
def test_frames_without_an_action_object_follow_the_chosen_policy_and_are_counted(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    rgb = np.random.default_rng(3).integers(0, 255, (*SIZE, 3), dtype=np.uint8)
    item = FrameItem("hotel-empty", 0, "test hotel empty", rgb=rgb, mask=np.zeros(SIZE, bool), meta={"kind": "visual"})
    add_frames(activity="hotel", sequence="nothing", items=iter([item]), mask_status=Status.REVIEWED)
    hotel = frames_by_activity()["hotel"]
    probs = {f.id: CenterPrior().predict(rgb_of(f), None) for f in hotel}
    masks = {f.id: truth_mask(f) for f in hotel}
    empty = next(fid for fid, m in masks.items() if not m.any())
    own = {fid: score_maps([probs[fid]], [masks[fid]]).max_f for fid in masks if fid != empty}

    pooled = scoring.build_report(run_ids=[], study_ids=[])
    assert pooled.provenance.empty_frames == {"cooking": 0, "hotel": 1}
    assert row(pooled, "centre prior").cells["hotel"].n_frames == 4  # pooled: its false positives count
    assert "Frames without action-object pixels: 1 (hotel 1); pooled counts their false positives" in pooled.to_table()

    left = scoring.build_report(run_ids=[], study_ids=[], metric="ois-mean")  # the default: leave-out
    cell = row(left, "centre prior").cells["hotel"]
    assert cell.n_frames == 3 and cell.max_f == pytest.approx(np.mean(list(own.values())), abs=1e-12)
    assert "policy leave-out: left out of the per-frame means (our choice" in left.to_table()
    assert json.loads(left.to_json())["empty_frames"]["by_activity"] == {"cooking": 0, "hotel": 1}
    zero = row(scoring.build_report(run_ids=[], study_ids=[], metric="ois-mean", empty="zero"), "centre prior").cells["hotel"]
    assert zero.n_frames == 4 and zero.max_f == pytest.approx(sum(own.values()) / 4, abs=1e-12)
    one = row(scoring.build_report(run_ids=[], study_ids=[], metric="ois-mean", empty="one-if-empty"), "centre prior").cells["hotel"]
    predicts_nothing = float(probs[empty].max() < 99 / 100)  # empty at the highest threshold: a perfect frame
    assert one.max_f == pytest.approx((sum(own.values()) + predicts_nothing) / 4, abs=1e-12)
    frames = scoring.frame_table(activity="hotel")
    assert [line.no_truth for line in frames.lines].count(True) == 1
    assert next(line for line in frames.lines if line.no_truth).scores["baseline:center"] == (None, None, None)
    with pytest.raises(scoring.ScoringProblem, match="empty: must be one of leave-out, zero, one-if-empty") as info:
        scoring.build_report(run_ids=[], study_ids=[], empty="skip")
    assert info.value.field == "empty"


@pytest.mark.one_database
def test_the_conventions_and_thresholds_against_direct_computations(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    frames = frames_by_activity()["hotel"]
    probs = [CenterPrior().predict(rgb_of(f), None) for f in frames]
    masks = [truth_mask(f) for f in frames]
    own = [score_maps([p], [m]) for p, m in zip(probs, masks)]  # each frame's own curve

    ois_mean = row(scoring.build_report(run_ids=[], study_ids=[], metric="ois-mean"), "centre prior").cells["hotel"]
    assert ois_mean.max_f == pytest.approx(np.mean([s.max_f for s in own]), abs=1e-12)
    assert ois_mean.ap == pytest.approx(np.mean([s.ap for s in own]), abs=1e-12)
    mean_curve = row(scoring.build_report(run_ids=[], study_ids=[], metric="mean-curve"), "centre prior").cells["hotel"]
    expected = score_maps(probs, masks, metric="mean-curve")
    assert (mean_curve.max_f, mean_curve.ap) == pytest.approx((expected.max_f, expected.ap), abs=1e-12)

    # OIS: each frame's counts at its own best threshold (the highest on ties), summed, then F.
    at_best = []
    for p, m, s in zip(probs, masks, own):
        k = int(np.flatnonzero(s.f == s.f.max())[-1])
        counts = count_stats(p, m)
        at_best.append([counts.tp[k], counts.fp[k], counts.fn[k]])
    tp, fp, fn = np.sum(at_best, axis=0)
    precision, recall = tp / (tp + fp), tp / (tp + fn)
    ods_ois = scoring.build_report(run_ids=[], study_ids=[], metric="ods-ois")
    cell = row(ods_ois, "centre prior").cells["hotel"]
    assert ods_ois.statistics() == ["max_f", "ois", "ap"] and ods_ois.label("max_f") == "ODS"
    assert cell.values["ois"] == pytest.approx(2 * precision * recall / (precision + recall), abs=1e-12)
    pooled = score_maps(probs, masks)
    assert (cell.max_f, cell.ap) == (pooled.max_f, pooled.ap)  # ODS and AP are the pooled numbers
    assert cell.too_few and cell.ci == {"max_f": None, "ois": None, "ap": None}  # 3 frames: n too small

    coarse = scoring.build_report(run_ids=[], study_ids=[], thresholds=9)
    assert row(coarse, "centre prior").cells["hotel"].ap == score_maps(probs, masks, thresholds=9).ap
    assert len(row(coarse, "AOP").curves["hotel"].precision) == 9
    for bad, field in ((dict(thresholds=0), "thresholds"), (dict(metric="mean"), "metric"), (dict(frames="some"), "frames"),
                       (dict(resamples=-1), "resamples"), (dict(seed=-1), "seed")):  # fmt: skip
        with pytest.raises(scoring.ScoringProblem) as info:
            scoring.build_report(**bad)
        assert info.value.field == field


@pytest.mark.one_database
def test_intervals_follow_resamples_and_seed(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", n=MIN_FRAMES, seed=2)
    one = scoring.build_report(run_ids=[], study_ids=[])
    assert one.to_json() == scoring.build_report(run_ids=[], study_ids=[]).to_json()  # seeded: the same intervals
    other = scoring.build_report(run_ids=[], study_ids=[], seed=5)
    cell, moved = row(one, "centre prior").cells["hotel"], row(other, "centre prior").cells["hotel"]
    assert cell.max_f == moved.max_f and cell.ci["max_f"] != moved.ci["max_f"]
    none = scoring.build_report(run_ids=[], study_ids=[], resamples=0)
    assert row(none, "centre prior").cells["hotel"].ci == {"max_f": None, "ap": None}
    assert row(none, "centre prior").cells["hotel"].max_f == cell.max_f


# --------------------------------------------------------------------------
# Model rows (held-out predictions of completed training runs) and seed groups


def make_run(name: str, *, held_out: list[str], folds: str = "loao", seed: int = 0, config: dict | None = None, maps=None) -> TrainingRun:
    """A done run of egonet-lite with a stored 16-bit prediction for every frame of ``held_out`` activities.

    Every other labelled frame gets a prediction too, but not held out:
    scoring must ignore it. ``maps(frame, rng)`` gives a prediction (default: noise).
    """
    rng = np.random.default_rng(seed)
    run = TrainingRun(
        name=name, model_name="egonet-lite", folds=FoldsMode(folds), epochs=1, device="cpu", seed=seed, status=RunStatus.DONE,
        config=config or {},
    )  # fmt: skip
    db.session.add(run)
    db.session.flush()
    checkpoint = Checkpoint(run_id=run.id, fold="fold", path=f"run-{run.id}/fold.pt", epochs=1)
    db.session.add(checkpoint)
    db.session.flush()
    for activity, frames in frames_by_activity().items():
        for frame in frames:
            prob = rng.random((frame.height, frame.width)) if maps is None else maps(frame, rng)
            path = media.store(egonet_io.encode_probability_png(prob.astype(np.float32)), ".png")
            db.session.add(Prediction(run_id=run.id, checkpoint_id=checkpoint.id, frame_id=frame.id, path=path, held_out=activity in held_out))
    db.session.commit()
    return run


def stored_prediction(run: TrainingRun, frame: Frame) -> np.ndarray:
    """The map as stored (what the run predicted, to 16 bits), read straight from its PNG."""
    path = db.session.execute(db.select(Prediction.path).filter_by(run_id=run.id, frame_id=frame.id)).scalar_one()
    return cv2.imread(str(media.local_path(path)), cv2.IMREAD_UNCHANGED).astype(np.float32) / 65535.0


def test_model_rows_score_held_out_predictions_only(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    loao = make_run("lite loao", held_out=["cooking", "hotel"], seed=3)
    single = make_run("lite single", held_out=["hotel"], folds="single", seed=4)
    report = scoring.build_report(study_ids=[], baselines=False)
    # Newest first, named by model and run.
    assert [(r.name, r.kind) for r in report.rows] == [(f"egonet-lite (run {single.id})", "model"), (f"egonet-lite (run {loao.id})", "model")]
    assert row(report, f"egonet-lite (run {single.id})").detail == "lite single, single folds, seed 4"
    frames = frames_by_activity()
    for run, activities in ((loao, ["cooking", "hotel"]), (single, ["hotel"])):
        got = row(report, f"egonet-lite (run {run.id})")
        assert sorted(got.cells) == activities  # cooking's predictions of the single run are not held out
        for activity in activities:
            probs = [stored_prediction(run, f) for f in frames[activity]]
            expected = score_maps(probs, [truth_mask(f) for f in frames[activity]])
            assert_cell(got.cells[activity], expected, 3)
    assert report.partial_means()  # the single run has hotel only
    assert not report.complete(row(report, f"egonet-lite (run {single.id})"))

    one = scoring.build_report(run_ids=[loao.id], study_ids=[], baselines=False)
    assert [r.name for r in one.rows] == [f"egonet-lite (run {loao.id})"]
    unfinished = TrainingRun(name="x", model_name="egonet-lite", folds=FoldsMode.LOAO, epochs=1, device="cpu", seed=0, status=RunStatus.RUNNING)
    db.session.add(unfinished)
    db.session.commit()
    for run_id in (unfinished.id, 999):
        with pytest.raises(scoring.ScoringProblem) as info:
            scoring.build_report(run_ids=[run_id])
        assert info.value.field == "runs" and f"run {run_id} is not a completed training run" in str(info.value)


def config_of(seed: int, *, epochs: int = 6, device: str = "cpu") -> dict:
    """A run's recorded configuration, as ``training.create_run`` writes it."""
    train = {"model": "egonet-lite", "folds": "loao", "epochs": epochs, "seed": seed, "device": device, "lr": 0.02, "batch_size": 4}
    return {"train": train, "activity_ids": None, "activities": ["cooking", "hotel"], "frames": 6}


def test_runs_that_differ_only_in_their_seed_are_one_row_with_their_spread(ctx):
    add_activity("cooking", n=MIN_FRAMES, seed=1)
    add_activity("hotel", n=MIN_FRAMES, seed=2)
    seeds = [make_run(f"seed {s}", held_out=["cooking", "hotel"], seed=s, config=config_of(s, device="cuda" if s else "cpu")) for s in (0, 1, 2)]
    longer = make_run("longer", held_out=["cooking", "hotel"], seed=0, config=config_of(0, epochs=12))
    report = scoring.build_report(study_ids=[], baselines=False)
    group_key = "seeds:" + ",".join(str(r.id) for r in reversed(seeds))  # newest first, as the runs are listed
    assert [r.key for r in report.rows] == [f"run:{longer.id}", group_key]
    group = report.row(group_key)
    assert group.name == "egonet-lite (3 seeds)" and group.kind == "model"
    assert [m.key for m in group.members] == [f"run:{r.id}" for r in reversed(seeds)]
    assert all(m.group == group_key for m in group.members) and [m.seed for m in group.members] == [2, 1, 0]
    for activity in ("cooking", "hotel"):
        values = [m.cells[activity].max_f for m in group.members]
        alone = scoring.build_report(run_ids=[seeds[0].id], study_ids=[], baselines=False).rows[0].cells[activity]
        assert group.members[-1].cells[activity].max_f == alone.max_f  # each run as on its own
        cell = group.cells[activity]
        assert cell.max_f == pytest.approx(np.mean(values), abs=1e-12)
        assert cell.sd["max_f"] == pytest.approx(np.std(values, ddof=1), abs=1e-12) and cell.sd["max_f"] > 0
        lo, hi = cell.ci["max_f"]
        assert lo <= cell.max_f <= hi
    assert group.mean.max_f == pytest.approx(np.mean([m.mean.max_f for m in group.members]), abs=1e-12)
    # Only top-level rows compete for best; the group's runs never do.
    assert all(not (set(keys) & {m.key for m in group.members}) for keys in report.best().values())
    data = json.loads(report.to_json())
    by_key = {r["key"]: r for r in data["rows"]}
    assert by_key[group_key]["members"] == [m.key for m in group.members]
    assert by_key[f"run:{seeds[0].id}"]["group"] == group_key
    assert by_key[group_key]["cells"]["hotel"]["max_f_sd"] == pytest.approx(group.cells["hotel"].sd["max_f"])


def test_a_paired_comparison_rejects_a_real_difference_and_not_identical_rows(ctx):
    for seed, name in enumerate(("cooking", "hotel")):
        add_activity(name, n=MIN_FRAMES, seed=seed)
    truth = {f.id: truth_mask(f) for fs in frames_by_activity().values() for f in fs}
    good = make_run("good", held_out=["cooking", "hotel"], seed=1, maps=lambda f, rng: np.clip(0.8 * truth[f.id] + 0.3 * rng.random(truth[f.id].shape), 0, 1))
    noisy = make_run("noisy", held_out=["cooking", "hotel"], seed=2)
    a, b = f"run:{good.id}", f"run:{noisy.id}"
    report = scoring.build_report(study_ids=[], baselines=False, compare_keys=(a, b))
    comparison = report.comparison
    assert comparison.a == (a, f"egonet-lite (run {good.id})") and comparison.statistics == ("max_f", "ap")
    head = comparison.headline()
    assert head.value == pytest.approx(row(report, comparison.a[1]).mean.max_f - row(report, comparison.b[1]).mean.max_f, abs=1e-12)
    assert head.p_value < 0.01 and head.ci[0] > 0 and head.n_frames == 2 * MIN_FRAMES
    assert all(d["max_f"].p_value < 0.05 for d in comparison.activities.values())
    same = scoring.build_report(study_ids=[], baselines=False, compare_keys=(a, a)).comparison
    assert same.headline().value == 0 and same.headline().p_value == 1.0
    assert all(d.p_value == 1.0 for ds in same.activities.values() for d in ds.values())
    with pytest.raises(scoring.ScoringProblem, match="there is no row 'run:999'") as info:
        scoring.build_report(study_ids=[], baselines=False, compare_keys=(a, "run:999"))
    assert info.value.field == "compare"


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
    assert f"run {run.id}: 1 held-out frame no longer has a ground truth and was left out." in report.notes


def test_a_run_whose_maps_cannot_be_scored_is_a_note_not_an_error(ctx, app):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    run = make_run("lite", held_out=["cooking"])
    prediction = db.session.execute(db.select(Prediction).filter_by(run_id=run.id, held_out=True)).scalars().first()
    prediction.path = media.store(egonet_io.encode_png(np.zeros((10, 10), np.uint16)), ".png")  # not the frame's size
    db.session.commit()
    report = scoring.build_report(study_ids=[])
    assert [r.name for r in report.rows] == BASELINE_ROWS
    assert any(note.startswith(f"egonet-lite (run {run.id}) could not be scored:") and "10x10" in note for note in report.notes)
    assert len(list((Path(app.config["CACHE_ROOT"]) / "scores").glob("*.npz"))) == len(BASELINE_ROWS)  # the baselines only


@pytest.mark.slow
@pytest.mark.one_database
def test_a_small_trained_run_scores_as_a_direct_computation_on_its_held_out_maps(app, runner, tmp_path):
    import torch

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
    data = json.loads(result.stdout)
    (got,) = data["rows"]
    with app.app_context():
        (run,) = training.completed_runs()
        assert got["name"] == f"egonet-lite (run {run.id})" and got["kind"] == "model" and got["seed"] == 0
        by_activity: dict[str, tuple[list, list]] = {}
        for frame, probability in training.held_out_predictions(run):
            probs, masks = by_activity.setdefault(frame.sequence.activity.name, ([], []))
            probs.append(probability)
            masks.append(truth_mask(frame))
    assert sorted(by_activity) == ["cooking", "dining"]
    for activity, (probs, masks) in by_activity.items():
        expected = score_maps(probs, masks)
        cell = got["cells"][activity]
        assert (cell["max_f"], cell["ap"], cell["n_frames"]) == (expected.max_f, expected.ap, len(probs))
        if len(probs) >= MIN_FRAMES:
            assert cell["max_f_ci"][0] <= cell["max_f"] <= cell["max_f_ci"][1]
        else:  # n too small: the estimate without an interval
            assert cell["max_f_ci"] is None and cell["too_few_frames"]
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
    monkeypatch.setattr(scoring_sources, "baseline_stats", lambda key, *a: scored.append(key) or baseline_stats(key, *a))

    again = scoring.build_report(study_ids=[])
    assert scored == []  # read back
    assert again.to_json() == first.to_json()
    # The same per-frame counts serve every convention, frame choice and resampling.
    for view in (dict(metric="ois-mean", empty="zero"), dict(metric="mean-curve"), dict(metric="ods-ois", frames="each"), dict(resamples=50, seed=3)):
        scoring.build_report(study_ids=[], **view)
    assert scored == []
    assert scoring.build_report(study_ids=[], use_cache=False).to_json() == first.to_json()
    assert scored == ["run", *BASELINES]

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
    assert scored == ["run", *BASELINES]
    assert fresh.to_json() == first.to_json()  # the masks and maps themselves did not change


def test_an_unreadable_or_old_cache_file_is_scored_again(ctx, app):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    first = scoring.build_report(run_ids=[], study_ids=[])
    folder = Path(app.config["CACHE_ROOT"]) / "scores"
    path = sorted(folder.glob("*.npz"))[0]
    (folder / "0123.json").write_text('{"stats": {}, "notes": []}')  # a version 1 file: never read
    for junk in (b"PK\x03\x04 truncated", b"", b"not a zip at all"):
        path.write_bytes(junk)
        assert scoring.build_report(run_ids=[], study_ids=[]).to_csv() == first.to_csv()
        assert path.read_bytes()[:2] == b"PK"  # rewritten
    # Statistics of another shape (another number of thresholds) are not used either.
    assert scoring_cache.read_cached(path, 99) is not None and scoring_cache.read_cached(path, 9) is None


def test_rows_carry_the_papers_names(ctx):
    add_activity("cooking", seed=1)
    add_activity("hotel", seed=2)
    runs = {}
    for model in ("egonet", "deeplab-rgb", "deeplab-dhg", "egonet-lite"):
        runs[model] = make_run(model, held_out=["cooking", "hotel"])
        runs[model].model_name = model
    db.session.commit()
    names = [r.name for r in scoring.build_report(study_ids=[], resamples=0).rows]
    assert names == [f"egonet-lite (run {runs['egonet-lite'].id})", f"DeepLab-DHG (run {runs['deeplab-dhg'].id})",
                     f"DeepLab-RGB (run {runs['deeplab-rgb'].id})", f"EgoNet (run {runs['egonet'].id})",
                     *BASELINE_ROWS]  # newest run first  # fmt: skip
