"""The baselines through the scoring service: fitted per leave-one-activity-out fold, never reading the scored frame's answers.

* Honesty: change the ground truth of a scored frame (its action-object
  mask and every instance's mask); the maps the scoring service gives *that
  frame* do not change, for every baseline. Changing it does change the
  maps of the other activities' frames for the learned baselines (their
  folds train on it), which shows the test can see a change.
* The fitted folds are cached per fold: a second report fits nothing, and
  an edited frame refits only the folds that train on it.
* A scoring request sends long fits to the worker (a real worker process)
  and shows the rows once it is done.
"""

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from app.extensions import db
from app.models import Annotation, is_hand
from app.queue import current_huey
from app.services import ground_truth, media
from app.services.demo import create_demo
from app.services import scoring
from app.services.scoring import fitting
from app.tasks import score_baselines
from app.services.scoring import sources as scoring_sources
from egonet import io as egonet_io
from egonet.baselines import BASELINES, TrainedBaseline, fit_folds, is_trained
from egonet.metrics import score_maps
from tests.app.test_scoring import add_activity, frames_by_activity

ROOT = Path(__file__).resolve().parents[2]


def maps_of(key: str) -> dict[int, np.ndarray]:
    truth = scoring_sources.load_truth()
    return {frame.id: prob for frame, prob in scoring_sources.baseline_maps(key, truth, [], lambda n: None)}


def rewrite_truth(frame_id: int, mask: np.ndarray) -> None:
    """Give a frame's ground truth a new action-object mask, and every instance of it the same new mask and swapped labels.

    The labels swap: a hand becomes a cup and an object a hand, so the
    frame's answers for Handled+Viewed-Obj's hand detector change too.
    """
    annotation = ground_truth.ground_truths([frame_id])[frame_id]
    path = media.store(egonet_io.encode_png(mask.astype(np.uint8) * 255), ".png")
    annotation.mask_path = path
    for instance in annotation.instances:
        instance.mask_path = path
        instance.label = "cup" if is_hand(instance.label) else "hand"
    annotation.review_comment = "redrawn"
    db.session.commit()


@pytest.mark.one_database
@pytest.mark.parametrize("key", list(BASELINES))
def test_a_scored_frames_own_masks_never_change_its_map(ctx, key):
    for seed, name in enumerate(("cooking", "hotel", "desk work")):
        add_activity(name, seed=seed, hands=True)  # hands labelled: Handled+Viewed-Obj's detector learns from them
    frames = frames_by_activity()
    before = maps_of(key)
    scored = frames["cooking"][1]
    h, w = before[scored.id].shape
    flipped = np.zeros((h, w), bool)
    flipped[h // 2 :, : w // 3] = True  # far from cooking's box, and a different size
    rewrite_truth(scored.id, flipped)
    after = maps_of(key)
    for frame in frames["cooking"]:  # the fold of cooking never trains on cooking's frames
        np.testing.assert_array_equal(after[frame.id], before[frame.id], err_msg=f"{key} read frame {frame.id}'s answers")
    changed = [f.id for a in ("hotel", "desk work") for f in frames[a] if not np.array_equal(after[f.id], before[f.id])]
    if is_trained(key):  # the other folds did train on the edited frame: the test sees their change
        assert changed, f"{key}: no other fold changed, so this test could not have seen a leak"
    else:
        assert not changed


def test_folds_are_cached_per_fold_and_refitted_only_where_the_training_frames_changed(ctx, monkeypatch):
    for seed, name in enumerate(("cooking", "hotel", "desk work")):
        add_activity(name, seed=seed)
    key = next(k for k in BASELINES if is_trained(k))
    fitted: list[str] = []
    real = fitting.fit_folds

    def counting(make, frames, *, folds=None, on_frame=None):
        fitted.extend(folds)
        return real(make, frames, folds=folds, on_frame=on_frame)

    monkeypatch.setattr(fitting, "fit_folds", counting)
    first = maps_of(key)
    assert sorted(fitted) == ["cooking", "desk work", "hotel"]
    fitted.clear()
    assert {k: v.tobytes() for k, v in maps_of(key).items()} == {k: v.tobytes() for k, v in first.items()}
    assert fitted == []  # read back
    files = sorted((Path(ctx.config["CACHE_ROOT"]) / "baselines").glob(f"{key}-*.npz"))
    assert len(files) == 3
    rewrite_truth(frames_by_activity()["hotel"][0].id, np.ones(first[next(iter(first))].shape, bool))
    maps_of(key)
    assert sorted(fitted) == ["cooking", "desk work"]  # hotel's fold never trained on hotel
    # The fold files are a cache: one deleted, or not a fold file any more, is fitted again, alone.
    fitted.clear()
    truth = scoring_sources.load_truth()
    fitting.fold_path(key, truth, "hotel").unlink()
    fitting.fold_path(key, truth, "cooking").write_bytes(b"not a zip")
    maps_of(key)
    assert sorted(fitted) == ["cooking", "hotel"]


def test_the_fold_files_hold_plain_data_that_fits_like_the_protocol(ctx):
    for seed, name in enumerate(("cooking", "hotel")):
        add_activity(name, seed=seed)
    truth = scoring_sources.load_truth()
    for key in (k for k in BASELINES if is_trained(k)):
        folds = fitting.fit_missing(key, truth)
        frames = {a: [fitting.training_frame(f, truth.annotations[f.id]) for f in fs] for a, fs in truth.by_activity().items()}
        direct = fit_folds(BASELINES[key], frames)
        for activity, model in folds.items():
            assert isinstance(model, TrainedBaseline)
            with np.load(fitting.fold_path(key, truth, activity), allow_pickle=False) as data:
                assert "meta" in data.files
            for name, value in model.state().items():
                np.testing.assert_array_equal(value, direct[activity].state()[name])


@pytest.mark.slow
def test_a_long_fit_goes_to_the_worker_and_its_rows_appear_when_it_is_done(app, database_url, tmp_path, admin_client):
    app.config["BASELINE_INLINE_S"] = 0.0  # every learned baseline counts as long
    learned = fitting.trained_keys()
    with app.app_context():
        for seed, name in enumerate(("cooking", "hotel")):
            add_activity(name, seed=seed)
    page = admin_client.get("/scores/").get_data(as_text=True)
    assert 'data-row="baseline:aop"' not in page and page.count("being fitted per fold and scored by the worker") == 1
    assert 'data-row="baseline:gbvs"' in page  # not trained: scored in the request
    again = admin_client.get("/scores/").get_data(as_text=True)  # queued once, not once per view
    assert "being fitted per fold" in again
    with app.app_context():
        assert current_huey().pending_count() == 1

    env = dict(
        os.environ,
        EGONET_QUEUE_URL=app.config["QUEUE_URL"],
        FLASK_SQLALCHEMY_DATABASE_URI=database_url,
        FLASK_SECRET_KEY="worker-test-secret-key-0123456789abcdef",
        FLASK_STORAGE_URL=app.config["STORAGE_URL"],
        FLASK_CACHE_ROOT=app.config["CACHE_ROOT"],
        OMP_NUM_THREADS="1",
    )
    worker = subprocess.Popen([sys.executable, "-m", "flask", "--app", "app", "egonet", "worker"],
                              cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            page = admin_client.get("/scores/").get_data(as_text=True)
            if all(f'data-row="baseline:{key}"' in page for key in learned):
                break
            time.sleep(0.5)
    finally:
        worker.terminate()
        out = worker.communicate(timeout=20)[0]
    assert all(f'data-row="baseline:{key}"' in page for key in learned), out[-3000:]
    assert "being fitted per fold" not in page
    with app.app_context():
        assert not list((Path(app.config["CACHE_ROOT"]) / "baselines").glob("queued-*"))
        assert db.session.execute(db.select(Annotation)).first() is not None


@pytest.fixture
def registry():
    """The registry as it was, back after the test (the docs' example adds a line to it)."""
    before = dict(BASELINES)
    yield BASELINES
    BASELINES.clear()
    BASELINES.update(before)


def test_the_docs_example_of_a_new_baseline_is_one_module_and_one_registry_line(ctx, registry):
    doc = (ROOT / "docs" / "science.md").read_text()
    block = re.search(r"```python\n(.*?class Brightness.*?)```", doc, re.S).group(1)
    assert len(block.strip().splitlines()) <= 16
    exec(compile(block, "docs/science.md", "exec"), {})
    assert is_trained("brightness")
    for seed, name in enumerate(("cooking", "hotel")):
        add_activity(name, seed=seed)
    report = scoring.build_report(run_ids=[], study_ids=[])
    row = next(r for r in report.rows if r.key == "baseline:brightness")
    assert row.name == "brightness" and row.detail == "fitted per fold under leave-one-activity-out"
    assert set(row.cells) == {"cooking", "hotel"} and all(c.n_frames == 3 for c in row.cells.values())


def test_the_handled_rows_name_says_where_each_folds_hands_come_from(ctx):
    add_activity("cooking", seed=0, hands=True)
    add_activity("hotel", seed=1, hands=True)
    add_activity("desk work", seed=2)  # no hand labelled here
    truth = scoring_sources.load_truth()
    # min_frames is 5: the fold of desk work learns from 6 labelled hands, the two others have 3 (skin colour).
    assert scoring_sources.baseline_name("handled", truth) == (
        "Handled+Viewed-Obj (hands: learned, 6 frames a fold; skin colour in 2 folds)")
    folds = fitting.fit_missing("handled", truth)
    assert {a: m.hands for a, m in folds.items()} == {
        "cooking": "skin colour", "hotel": "skin colour", "desk work": "learned, 6 frames"}
    report = scoring.build_report(run_ids=[], study_ids=[])
    assert "Handled+Viewed-Obj (hands: learned, 6 frames a fold; skin colour in 2 folds)" in [r.name for r in report.rows]


@pytest.mark.slow
@pytest.mark.one_database
def test_the_handled_row_with_learned_hands_beats_a_random_map_on_the_demo(ctx):
    create_demo(frames_per_activity=8, unlabelled_fraction=0, width=160, height=120)
    truth = scoring_sources.load_truth()
    assert scoring_sources.baseline_name("handled", truth).startswith("Handled+Viewed-Obj (hands: learned, ")
    maps = dict(scoring_sources.baseline_maps("handled", truth, [], lambda n: None))
    frames = sorted(maps, key=lambda frame: frame.id)
    masks = [truth.mask(frame.id) for frame in frames]
    ours = score_maps([maps[frame] for frame in frames], masks)
    rng = np.random.default_rng(0)
    chance = score_maps([rng.random(m.shape).astype(np.float32) for m in masks], masks)
    assert ours.max_f > chance.max_f + 0.05 and ours.ap > chance.ap + 0.03, (ours, chance)  # measured: +0.074, +0.049


@pytest.mark.slow
@pytest.mark.one_database
def test_every_baseline_beats_a_random_map_on_the_demo(ctx):
    create_demo(frames_per_activity=6, unlabelled_fraction=0, width=160, height=120)
    report = scoring.build_report(run_ids=[], study_ids=[], resamples=0)
    truth = scoring_sources.load_truth()
    masks = [truth.mask(frame.id) for frame in truth.frames]
    rng = np.random.default_rng(0)
    chance = score_maps([rng.random(m.shape).astype(np.float32) for m in masks], masks)  # pooled, as the rows' "overall"
    assert [r.key for r in report.rows] == [f"baseline:{key}" for key in BASELINES]
    for r in report.rows:
        assert r.overall.n_frames == len(masks) == 42
        assert r.overall.max_f > chance.max_f or r.overall.ap > chance.ap, (r.name, r.overall.max_f, r.overall.ap, chance)


def test_a_failed_worker_fit_is_said_on_the_page_and_not_queued_again(app, admin_client):
    app.config["BASELINE_INLINE_S"] = 0.0
    with app.app_context():
        for seed, name in enumerate(("cooking", "hotel")):
            add_activity(name, seed=seed)
        fitting.worker_done(scoring_sources.load_truth(), 99, "ValueError: a mask of another size")
    page = admin_client.get("/scores/").get_data(as_text=True)
    assert "The worker could not fit the learned baselines not shown: ValueError: a mask of another size." in page
    assert 'data-row="baseline:aop"' not in page and 'data-row="baseline:gbvs"' in page
    with app.app_context():
        assert current_huey().pending_count() == 0


def test_a_frame_that_cannot_be_learned_from_is_a_note_and_the_worker_keeps_it(app, admin_client):
    app.config["BASELINE_INLINE_S"] = 0.0
    with app.app_context():
        for seed, name in enumerate(("cooking", "hotel")):
            add_activity(name, seed=seed)
        annotation = ground_truth.ground_truths([frames_by_activity()["hotel"][0].id]).popitem()[1]
        annotation.instances[0].mask_path = media.store(egonet_io.encode_png(np.full((8, 8), 255, np.uint8)), ".png")
        db.session.commit()  # an instance whose mask is not the frame's size
        assert score_baselines.func(99) == 3  # GBVS, centre, saliency: they learn nothing
    page = admin_client.get("/scores/").get_data(as_text=True)
    (note,) = re.findall(r"<li>The worker could not fit[^<]*</li>", page)  # said once
    assert "AOP could not be scored: instances[0] must be a bool (48, 64) mask" in note and 'data-row="baseline:aop"' not in page
    with app.app_context():
        assert current_huey().pending_count() == 0  # not queued again
