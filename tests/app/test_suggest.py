"""Proposals ("Suggest"): a trained run, or depth, handled or saliency without one, proposes a
frame's action-objects.

Most tests of a run give it a stored probability map (the suggestion reuses a
checkpoint's stored prediction of a frame, as it does after training): a
blurred, low-resolution copy of the true object, as a network's map looks.
Those that need a model train egonet-lite on demo frames at 32x24 for one
epoch (as tests/app/test_training.py does), which learns little: they check
the whole path, not the model.
"""

import cv2
import numpy as np
import pytest

from app.extensions import db
from app.models import Activity, Annotation, Frame, Instance, Status, User
from app.models.annotations import GrabCutState
from app.models.training import Checkpoint, FoldsMode, Prediction, RunStatus, TrainingRun
from app.services import labelling, media, training
from app.services.demo import create_demo
from app.services.importing import FrameItem, add_frames
from app.services.labelling import proposers
from egonet import io, synth
from tests.app.test_labelling import H, OBJECT, W, body, make_frames, rle, square, true_mask

TINY = {"model": "egonet-lite", "epochs": 1, "width": 32, "height": 24, "batch_size": 2, "device": "cpu"}


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


@pytest.fixture
def annotator(client, make_user):
    client.login_as(make_user("annotator", "ann"))
    return client


def user(name: str = "ann") -> User:
    return db.session.execute(db.select(User).filter_by(username=name)).scalar_one()


def network_like(mask: np.ndarray, *, factor: int = 8, shift: tuple[int, int] = (0, 0)) -> np.ndarray:
    """A map as a network at 1/factor of the size draws the object: blurred, blocky, perhaps off by a few pixels."""
    h, w = mask.shape
    small = cv2.resize(np.roll(mask, shift, axis=(0, 1)).astype(np.float32), (w // factor, h // factor), interpolation=cv2.INTER_AREA)
    return np.clip(cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR), 0, 1).astype(np.float32)


def stored_run(maps: dict[int, np.ndarray], *, threshold: float | None = 0.5, status=RunStatus.DONE, name="stored",
               model: str = "egonet-lite", activities: tuple[str, ...] = ("kitchen",)) -> int:
    """A finished run (trained on ``activities``) whose one checkpoint has stored maps of some frames
    (the file is never loaded: a suggestion reuses stored maps); returns its id."""
    run = TrainingRun(name=name, model_name=model, folds=FoldsMode.SINGLE, epochs=1, device="cpu", seed=0,
                      status=status, config={"activities": list(activities)})
    db.session.add(run)
    db.session.flush()
    training.files.put(f"run-{run.id}/single.pt", b"never loaded: the stored maps are used")
    metrics = {"max_f": 0.5} | ({"threshold": threshold} if threshold is not None else {})
    checkpoint = Checkpoint(run=run, fold="single", path=f"run-{run.id}/single.pt", epochs=1, metrics=metrics,
                            test_frame_ids=list(maps))
    db.session.add(checkpoint)
    db.session.flush()
    for frame_id, probability in maps.items():
        db.session.add(Prediction(run_id=run.id, checkpoint_id=checkpoint.id, frame_id=frame_id, held_out=True,
                                  path=media.store(io.encode_probability_png(probability), ".png")))
    db.session.commit()
    return run.id


def saved_mask(instance: Instance) -> np.ndarray:
    return io.read_mask(media.local_path(instance.mask_path))


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max(1, (a | b).sum()))


def own_annotation(frame_id: int, username: str = "ann") -> Annotation:
    return db.session.execute(
        db.select(Annotation).filter_by(frame_id=frame_id, author_id=user(username).id)
    ).scalar_one()


# --------------------------------------------------------------------------- regions of a map


def test_regions_drop_specks_and_maps_above_the_threshold_everywhere():
    p = np.zeros((100, 200), np.float32)
    p[10:30, 20:60] = 0.9  # 800 px: an object
    p[60:90, 120:180] = 0.7  # 1800 px, less probable per pixel but more mass
    p[95:97, 5:7] = 0.95  # 4 px: a speck (the minimum is 0.002 x 20000 = 40 px)
    regions, notes = labelling.proposal_regions(p, 0.5)
    assert [r.area for r in regions] == [1800, 800]  # by mass: 1260 before 720
    first = regions[1]
    assert first.box == (20, 10, 60, 30)
    assert first.band == 3  # GrabCut may move its edge 6 % of 40 px (2.4), at least 3 px
    assert regions[0].band == pytest.approx(0.06 * 60)
    assert notes == ["1 speck under 40 px dropped"]

    regions, notes = labelling.proposal_regions(p, 0.5, limit=1)
    assert [r.area for r in regions] == [1800] and "1 less probable region left out" in notes
    everywhere = np.full((100, 200), 0.6, np.float32)
    regions, notes = labelling.proposal_regions(everywhere, 0.5)
    assert regions == [] and "over 50% of the frame dropped" in notes[0]
    assert labelling.proposal_regions(p, 0.99) == ([], [])


def test_the_threshold_is_the_checkpoints_best_f_else_one_half(ctx):
    assert proposers.checkpoint_threshold(Checkpoint(metrics={"threshold": 0.31})) == (0.31, "checkpoint")
    for metrics in ({}, {"threshold": None}, {"threshold": 1.5}, {"threshold": True}):
        assert proposers.checkpoint_threshold(Checkpoint(metrics=metrics)) == (0.5, "default")


# --------------------------------------------------------------------------- suggesting


def test_a_proposal_is_refined_by_grabcut_and_overlaps_the_truth(app, annotator):
    """The map of a network at 1/8 of the size, 4 px off: GrabCut brings the proposal onto the object."""
    (frame_id,) = make_frames(app, n=1)
    probability = network_like(true_mask(), shift=(4, -4))
    with app.app_context():
        run_id = stored_run({frame_id: probability})
        raw = iou(probability >= 0.5, true_mask())
    response = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0})
    assert response.status_code == 200, response.get_json()
    data = response.get_json()
    s, ann = data["suggestion"], data["annotation"]
    assert s["run_id"] == run_id and s["source"] == "model" and s["proposed_by"] == f"run {run_id}"
    assert s["prediction"] == "stored" and s["threshold"] == 0.5
    assert s["threshold_source"] == "checkpoint" and s["held_out"] and s["checkpoint_choice"] == "its fold held this frame out"
    assert len(s["proposals"]) == 1 and s["reason"] == "trained on real frames like this one"
    assert s["message"] == f"Run {run_id}: trained on real frames like this one. It proposed 1 object: accept or reject it."
    (inst,) = ann["instances"]
    assert inst["key"] == s["proposals"][0] and inst["proposed_by_run_id"] == run_id and inst["proposal_source"] == "model"
    # Proposals alone claim nothing: the annotation is "todo" until one is accepted or edited.
    assert ann["status"] == "todo" and ann["version"] == 1 and ann["proposed_by_run_id"] == run_id
    with app.app_context():
        proposal = saved_mask(own_annotation(frame_id).instances[0])
        # Measured: the thresholded map alone 0.80, the proposal 0.95 (a random box of the object's size: 0.0-0.3).
        assert iou(proposal, true_mask()) > 0.9 > raw
    # The proposal's GrabCut session is the annotator's: strokes can correct it at once.
    assert annotator.get(f"/api/label/frames/{frame_id}/annotation").get_json()["grabcut"] == [inst["key"]]


def test_a_tiny_trained_run_suggests_on_a_frame_it_held_out(app, make_user):
    """The whole path with a real model: train, predict the held-out frame, propose, mark."""
    make_user("annotator", "ann")
    with app.app_context():
        create_demo(frames_per_activity=2, width=64, height=48)
        ids = tuple(db.session.execute(db.select(Activity.id).where(Activity.name.in_(["cooking", "dining"]))).scalars())
        run = training.execute_run(training.create_run(training.RunRequest(**TINY, folds="loao", activity_ids=ids)).id)
        cooking = db.session.execute(db.select(Frame).join(Frame.sequence).join(Activity).where(Activity.name == "cooking")).scalars().first()
        # The map the training stored is used; without it the checkpoint predicts (and stores) the frame.
        db.session.execute(db.delete(Prediction).where(Prediction.frame_id == cooking.id))
        db.session.commit()
        s = labelling.suggest_frame(cooking, user(), version=0, device="cpu")
        p = s.proposer
        assert p.run.id == run.id and p.checkpoint.fold == "cooking" and p.held_out
        assert p.why == "its fold held the activity 'cooking' out" and s.prediction == "computed"
        assert s.threshold == pytest.approx(p.checkpoint.metrics["threshold"]) and s.threshold_source == "checkpoint"
        stored = db.session.execute(db.select(Prediction).filter_by(frame_id=cooking.id)).scalar_one()
        assert stored.checkpoint_id == p.checkpoint.id and stored.held_out
        annotation = own_annotation(cooking.id)
        marked = [i for i in annotation.instances if i.proposed]
        assert [i.key for i in marked] == s.proposals and all(i.proposed_by_run_id == run.id for i in marked)
        assert annotation.proposed_by_run_id == run.id and annotation.proposed_by_checkpoint_id == p.checkpoint.id
        assert len(s.proposals) >= 1, s.summary()  # this run and frame give one (measured); the map's noise decides where
        # Asked again, the stored map is reused, and the pending proposals are replaced, not doubled.
        again = labelling.suggest_frame(cooking, user(), run_id=run.id, version=annotation.version)
        assert again.prediction == "stored" and again.replaced == len(s.proposals)
        assert [i.key for i in own_annotation(cooking.id).instances] == again.proposals


def test_proposals_go_beside_the_annotators_own_objects(app, annotator):
    (frame_id,) = make_frames(app, n=1)
    drawn = square(5, 25, 5, 30)
    saved = annotator.put(f"/api/label/frames/{frame_id}/annotation", json=body(0, drawn)).get_json()
    with app.app_context():
        stored_run({frame_id: network_like(true_mask())})
    data = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": saved["version"]}).get_json()
    keys = [i["key"] for i in data["annotation"]["instances"]]
    assert keys == ["k0", data["suggestion"]["proposals"][0]]
    assert data["annotation"]["instances"][0]["proposed_by_run_id"] is None
    with app.app_context():
        assert np.array_equal(saved_mask(own_annotation(frame_id).instances[0]), drawn)  # untouched

    # The object drawn by hand already: the model's region is that object again, left out.
    other = make_frames(app, n=1, activity="desk")[0]
    annotator.put(f"/api/label/frames/{other}/annotation", json=body(0, true_mask()))
    with app.app_context():
        stored_run({other: network_like(true_mask())}, name="second")
    data = annotator.post(f"/api/label/frames/{other}/suggest", json={"version": 1}).get_json()
    assert data["suggestion"]["proposals"] == [] and "1 region left out: already drawn" in data["suggestion"]["notes"]
    assert data["annotation"]["version"] == 1  # nothing written


# --------------------------------------------------------------------------- the mark: accept, edit


@pytest.fixture
def proposed(app, annotator):
    """A frame with one proposal on it: (frame id, the proposal's key, the annotation's version)."""
    (frame_id,) = make_frames(app, n=1)
    with app.app_context():
        stored_run({frame_id: network_like(true_mask())})
    data = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0}).get_json()
    return frame_id, data["suggestion"]["proposals"][0], data["annotation"]["version"]


def page_save(client, frame_id: int, version: int, key: str, mask: np.ndarray, **extra):
    """A save as the page sends it: every instance with its key and mask."""
    return client.put(f"/api/label/frames/{frame_id}/annotation",
                      json={"version": version, "instances": [{"key": key, "mask": rle(mask)}], **extra})


def test_accepting_clears_the_mark_and_moves_the_version(app, annotator, proposed):
    frame_id, key, version = proposed
    url = f"/api/label/frames/{frame_id}/annotation/proposals/accept"
    response = annotator.post(url, json={"version": version, "key": key})
    assert response.status_code == 200, response.get_json()
    data = response.get_json()
    assert data["version"] == version + 1 and data["instances"][0]["proposed_by_run_id"] is None
    assert data["status"] == "in_progress"  # accepted: the annotator's own, the frame is being labelled
    assert data["instances"][0]["proposal_source"] is None
    assert data["proposed_by_run_id"] is not None  # the annotation keeps where its objects came from
    again = annotator.post(url, json={"version": data["version"], "key": key})
    assert again.status_code == 409 and again.get_json()["fields"] == {"key": "not a proposal"}
    missing = annotator.post(url, json={"version": data["version"], "key": "nope"})
    assert missing.status_code == 404 and "key" in missing.get_json()["fields"]
    stale = annotator.post(url, json={"version": version, "key": key})
    assert stale.status_code == 409 and stale.get_json()["current_version"] == data["version"]


def test_a_save_keeps_the_mark_until_the_mask_changes(app, annotator, proposed):
    frame_id, key, version = proposed
    with app.app_context():
        mask = saved_mask(own_annotation(frame_id).instances[0])
    # The page saving the proposal as it is (a name given, say) keeps it a proposal.
    same = page_save(annotator, frame_id, version, key, mask, no_action_object=False).get_json()
    assert same["instances"][0]["proposed_by_run_id"] is not None
    named = annotator.put(f"/api/label/frames/{frame_id}/annotation", json={
        "version": same["version"], "instances": [{"key": key, "label": "mug", "mask": rle(mask)}]}).get_json()
    assert named["version"] == same["version"] + 1 and named["instances"][0]["proposed_by_run_id"] is not None
    # One pixel painted: an edit, the mark goes.
    painted = mask.copy()
    painted[0, 0] = True
    edited = page_save(annotator, frame_id, named["version"], key, painted).get_json()
    assert edited["instances"][0]["proposed_by_run_id"] is None
    back = page_save(annotator, frame_id, edited["version"], key, mask).get_json()
    assert back["instances"][0]["proposed_by_run_id"] is None  # undoing the edit does not make it a proposal again


def test_a_grabcut_step_on_a_proposal_clears_the_mark(app, annotator, proposed):
    frame_id, key, _ = proposed
    stroke = {"frame_id": frame_id, "instance": key, "points": [[20, 20]], "label": "bg", "radius": 3}
    assert annotator.post("/api/label/grabcut/stroke", json=stroke).status_code == 200
    with app.app_context():
        assert not own_annotation(frame_id).instances[0].proposed
        assert own_annotation(frame_id).status is Status.IN_PROGRESS  # edited: the annotator's own now


def test_done_is_refused_while_proposals_are_pending(app, annotator, proposed):
    frame_id, key, version = proposed
    with app.app_context():
        mask = saved_mask(own_annotation(frame_id).instances[0])
    refused = page_save(annotator, frame_id, version, key, mask, status="done")
    assert refused.status_code == 400 and "accept or reject each" in refused.get_json()["message"]
    assert "status" in refused.get_json()["fields"]
    accepted = annotator.post(f"/api/label/frames/{frame_id}/annotation/proposals/accept",
                              json={"version": version, "key": key}).get_json()
    done = page_save(annotator, frame_id, accepted["version"], key, mask, status="done")
    assert done.status_code == 200 and done.get_json()["status"] == "done"
    # Rejecting a proposal is deleting it, as any object: the frame can then be marked empty.
    assert done.get_json()["instances"][0]["proposed_by_run_id"] is None


def test_deleting_the_run_makes_its_pending_proposals_ordinary_objects(app, annotator, proposed):
    frame_id, _, _ = proposed
    with app.app_context():
        training.delete_run(db.session.get(TrainingRun, own_annotation(frame_id).instances[0].proposed_by_run_id))
        (instance,) = own_annotation(frame_id).instances
        assert not instance.proposed and instance.proposal_source is None and instance.proposed_by_run_id is None


# --------------------------------------------------------------------------- refusals


def held_bag(app) -> tuple[int, np.ndarray]:
    """A demo frame of a hand holding a bag, imported with its depth and intrinsics into the activity
    "shop": its id, and the bag's mask."""
    f = synth.render_frame("shopping", 1, seed=0, width=320, height=240)
    with app.app_context():
        add_frames(activity="shop", sequence="s1", items=[FrameItem("bag", 0, "bag", rgb=f.rgb, depth_m=f.depth_m, K=f.K)])
        return db.session.execute(db.select(Frame.id).where(Frame.source_name == "bag")).scalar_one(), f.mask


def test_without_a_run_suggest_proposes_from_depth_and_marks_the_source(app, annotator):
    frame_id, truth = held_bag(app)
    response = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0})
    assert response.status_code == 200, response.get_json()
    s, ann = response.get_json()["suggestion"], response.get_json()["annotation"]
    assert (s["source"], s["proposed_by"], s["run_id"], s["threshold_source"]) == ("depth", "depth", None, "source")
    assert s["message"].startswith("Depth: this frame has depth. It proposed ")
    assert [i["proposal_source"] for i in ann["instances"]] == ["depth"] * len(s["proposals"]) != []
    assert ann["proposed_by_run_id"] is None and all(i["proposed_by_run_id"] is None for i in ann["instances"])
    with app.app_context():
        ious = [iou(saved_mask(i), truth) for i in own_annotation(frame_id).instances]
    assert max(ious) > 0.9  # measured 0.98: the bag, refined by GrabCut with depth

    best = ann["instances"][int(np.argmax(ious))]["key"]
    accepted = annotator.post(f"/api/label/frames/{frame_id}/annotation/proposals/accept",
                              json={"version": ann["version"], "key": best}).get_json()
    assert [i["proposal_source"] for i in accepted["instances"] if i["key"] == best] == [None]


def test_without_depth_or_a_run_auto_is_the_handled_object_and_the_model_asks_for_training(app, annotator):
    (frame_id,) = make_frames(app, n=1)
    data = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0}).get_json()
    assert data["suggestion"]["source"] == "handled", data
    # The baseline keeps colour regions under 5 % of the frame: this red object (12 %) is not one of them.
    assert [i["proposal_source"] for i in data["annotation"]["instances"]] == ["handled"]
    version = data["annotation"]["version"]
    saliency = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": version, "source": "saliency"})
    assert saliency.status_code == 200 and saliency.get_json()["suggestion"]["replaced"] == 1
    version = saliency.get_json()["annotation"]["version"]

    response = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": version, "source": "model"})
    assert response.status_code == 409
    assert response.get_json()["message"].startswith("Train a model first:") and "depth, handled or saliency" in response.get_json()["message"]
    assert response.get_json()["fields"] == {"run_id": "no finished training run"}
    with app.app_context():
        stored_run({frame_id: network_like(true_mask())}, status=RunStatus.RUNNING)
    running = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": version, "source": "model"})
    assert running.status_code == 409 and running.get_json()["fields"] == {"run_id": "no finished training run"}


def test_the_hint_says_what_auto_uses_and_why_before_the_click(app, annotator):
    frame_id, _ = held_bag(app)
    train = "Train one for shop: the Training page, or flask egonet train --activities shop"
    page = annotator.get(f"/label/frames/{frame_id}").get_data(as_text=True)
    assert f'<p class="hint" id="suggest-hint">Auto uses depth: this frame has depth. {train}</p>' in page
    with app.app_context():
        frame = db.session.get(Frame, frame_id)
        # A run trained on activities that are not here (no frames of any kind): not for Auto, said so.
        elsewhere = stored_run({}, activities=("cooking", "dining"))
        choices = labelling.source_choices(frame)
        assert choices["hint"] == (f"Auto uses depth: this frame has depth. Run {elsewhere} was trained on frames no "
                                   f"longer here, not on real frames like this one: choose it above to try it anyway. {train}")
        assert [(c["source"], c["run_id"], c["label"], c["disabled"]) for c in choices["choices"]] == [
            ("auto", None, "Auto (depth)", False),
            ("depth", None, "Depth: the nearest compact surface", False),
            ("handled", None, "Handled: the colour region nearest the centre", False),
            ("saliency", None, "Saliency: spectral residual saliency", False),
            ("model", elsewhere, f"Run {elsewhere}: stored — trained on frames no longer here", False),
        ]
        trained_here = stored_run({}, activities=("shop",), name="shop run")
        assert labelling.source_choices(frame)["hint"].startswith(
            f"Auto uses run {trained_here}: trained on real frames like this one.")
    (plain,) = make_frames(app, n=1, activity="desk work")
    with app.app_context():
        choices = labelling.source_choices(db.session.get(Frame, plain))
    assert choices["choices"][1] == {"source": "depth", "run_id": None, "label": "Depth: this frame has none",
                                     "disabled": True}
    # egonet-lite reads DHG, which this RGB-only frame lacks: said before the click, Auto passes over the runs.
    assert [(c["label"], c["disabled"]) for c in choices["choices"] if c["source"] == "model"] == [
        (f"Run {trained_here}: shop run — needs depth (DHG): this frame has none", True),
        (f"Run {elsewhere}: stored — needs depth (DHG): this frame has none", True),
    ]
    assert choices["hint"] == ("Auto uses handled: no depth here; it proposes object-sized colour regions near the "
                               "centre. Train one for desk work: the Training page, or flask egonet train --activities 'desk work'")
    response = annotator.post(f"/api/label/frames/{plain}/suggest", json={"version": 0, "run_id": trained_here})
    assert response.status_code == 409 and response.get_json()["fields"] == {"run_id": "needs depth (DHG)"}


@pytest.mark.parametrize(
    ("request_body", "status", "field"),
    [
        ({"version": 0, "run_id": 999}, 404, "run_id"),
        ({"version": 0, "run_id": "one"}, 400, "run_id"),
        ({"version": 0, "run_id": 0}, 400, "run_id"),
        ({"version": -1}, 400, "version"),
        ({}, 400, "version"),
        ({"version": 0, "threshold": 0.2}, 400, "threshold"),
        ({"version": 0, "source": "model-free"}, 400, "source"),
        ({"version": 0, "source": "depth", "run_id": 1}, 400, "run_id"),
        ({"version": 0, "source": "depth"}, 409, "source"),  # the frame has no depth
        ({"version": 3}, 409, "version"),
    ],
)
def test_bad_requests_name_the_field(app, annotator, request_body, status, field):
    (frame_id,) = make_frames(app, n=1)
    with app.app_context():
        stored_run({frame_id: network_like(true_mask())})
    response = annotator.post(f"/api/label/frames/{frame_id}/suggest", json=request_body)
    assert response.status_code == status and field in response.get_json()["fields"], response.get_json()


def test_a_running_run_and_finished_or_empty_annotations_are_refused(app, annotator):
    first, second = make_frames(app, n=2)
    with app.app_context():
        running_id = stored_run({first: network_like(true_mask())}, status=RunStatus.RUNNING, name="running")
        stored_run({first: network_like(true_mask()), second: network_like(true_mask())})
    response = annotator.post(f"/api/label/frames/{first}/suggest", json={"version": 0, "run_id": running_id})
    assert response.status_code == 409 and response.get_json()["fields"] == {"run_id": "is running"}

    done = annotator.put(f"/api/label/frames/{first}/annotation", json=body(0, square(5, 25, 5, 30), status="done"))
    response = annotator.post(f"/api/label/frames/{first}/suggest", json={"version": done.get_json()["version"]})
    assert response.status_code == 409 and "reopen it" in response.get_json()["message"]
    assert response.get_json()["fields"] == {"status": "is done"}

    empty = annotator.put(f"/api/label/frames/{second}/annotation", json=body(0, no_action_object=True))
    response = annotator.post(f"/api/label/frames/{second}/suggest", json={"version": empty.get_json()["version"]})
    assert response.status_code == 409 and "no_action_object" in response.get_json()["fields"]


def test_only_labellers_may_suggest(app, client, make_user, proposed):
    frame_id, key, version = proposed
    client.login_as(make_user("reviewer", "rev"))
    assert client.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0}).status_code == 403
    accept = client.post(f"/api/label/frames/{frame_id}/annotation/proposals/accept", json={"version": version, "key": key})
    assert accept.status_code == 403


def test_a_slow_model_is_queued_for_the_worker(app, annotator, monkeypatch):
    (frame_id,) = make_frames(app, n=1)
    with app.app_context():
        run_id = stored_run({}, model="egonet-rgb")  # a VGG model, no stored map of the frame
    monkeypatch.setattr("torch.cuda.is_available", lambda: False)
    queued = []
    monkeypatch.setattr("app.tasks.suggest_frames", lambda *args: queued.append(args))
    response = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0})
    assert response.status_code == 202, response.get_json()
    assert response.get_json()["queued"] and "queued for the worker" in response.get_json()["message"]
    with app.app_context():
        assert queued == [(run_id, [frame_id], user().id, "auto", "model")]


# --------------------------------------------------------------------------- batches: the job and the CLI


def test_the_job_suggests_on_frames_and_skips_labelled_ones(app, make_user):
    from app.tasks import suggest_frames

    make_user("annotator", "ann")
    frames = make_frames(app, n=3)
    with app.app_context():
        run_id = stored_run({f: network_like(true_mask()) for f in frames})
        labelling.save_annotation(db.session.get(Frame, frames[2]), user(), {
            "version": 0, "instances": [], "no_action_object": True, "status": "done", "time_spent_delta_s": 0.0})
        assert suggest_frames.func(run_id, frames, user().id) == 2
        assert [len(own_annotation(f).instances) for f in frames] == [1, 1, 0]


def test_cli_suggests_in_the_foreground_or_queues(app, runner, make_user, monkeypatch):
    make_user("annotator", "ann")
    make_user("reviewer", "rev")
    frames = make_frames(app, n=3)
    with app.app_context():
        run_id = stored_run({f: network_like(true_mask()) for f in frames})
    result = runner.invoke(args=["egonet", "suggest", "--run", str(run_id), "--frames", f"{frames[0]},{frames[1]}", "--user", "ann"])
    assert result.exit_code == 0, result.output
    assert f"frame {frames[0]}: Run {run_id} proposed 1 object: accept or reject it." in result.output
    assert f"run {run_id}: 2 proposals on 2 frames for ann, 0 frames skipped" in result.output

    queued = []
    monkeypatch.setattr("app.tasks.suggest_frames", lambda *args: queued.append(args))
    result = runner.invoke(args=["egonet", "suggest", "--activity", "kitchen", "--user", "ann", "--queue", "--device", "cpu"])
    assert result.exit_code == 0, result.output
    with app.app_context():
        assert queued == [(None, frames, user().id, "cpu", "auto")]  # each frame's proposer is chosen in the job
    assert "3 frames queued for proposals by auto to ann" in result.output

    for args, message in [
        (["--user", "rev"], "rev is a reviewer"),
        (["--user", "nobody"], "there is no user 'nobody'"),
        (["--user", "ann", "--run", "999"], "there is no training run 999"),
        (["--user", "ann", "--frames", "1,x"], "give frame ids separated by commas"),
        (["--user", "ann", "--frames", "99999"], "no frame with id 99999"),
        (["--user", "ann", "--run", str(run_id), "--source", "depth"], "a run proposes as the model source, not depth"),
    ]:
        result = runner.invoke(args=["egonet", "suggest", *args])
        assert result.exit_code != 0 and message in result.output, (args, result.output)


def test_the_grabcut_sessions_of_replaced_proposals_go(app, annotator, proposed):
    frame_id, key, version = proposed
    data = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": version}).get_json()
    assert data["suggestion"]["replaced"] == 1
    with app.app_context():
        keys = set(db.session.execute(db.select(GrabCutState.instance_key)).scalars())
    assert keys == set(data["suggestion"]["proposals"]) and key not in keys
    assert data["annotation"]["status"] == Status.TODO.value


# --------------------------------------------------------------------------- a model that learnt something


def random_box_iou(truth: np.ndarray, rng: np.random.Generator, n: int = 200) -> float:
    """Mean IoU with the truth of boxes of the truth's size placed anywhere in the frame."""
    h, w = truth.shape
    ys, xs = np.nonzero(truth)
    bh, bw = np.ptp(ys) + 1, np.ptp(xs) + 1
    out = []
    for _ in range(n):
        y0, x0 = rng.integers(0, h - bh + 1), rng.integers(0, w - bw + 1)
        box = np.zeros_like(truth)
        box[y0 : y0 + bh, x0 : x0 + bw] = True
        out.append(iou(box, truth))
    return float(np.mean(out))


@pytest.mark.slow
@pytest.mark.one_database
def test_a_trained_run_proposes_held_out_objects_far_better_than_a_random_box(app, make_user):
    """egonet-lite, 8 epochs at 64x48 on 6 demo frames per activity (128x96), one split (about a minute).

    Measured on its 14 held-out frames: proposals IoU 0.20 median / 0.32 mean
    with the truth; a box of the object's size anywhere in the frame: 0.09 mean.
    """
    from app.services import ground_truth

    make_user("annotator", "ann")
    with app.app_context():
        create_demo(frames_per_activity=6, width=128, height=96)
        request = training.RunRequest(**(TINY | {"epochs": 8, "width": 64, "height": 48}), folds="single")
        run = training.execute_run(training.create_run(request).id)
        (checkpoint,) = run.checkpoints
        rng = np.random.default_rng(0)
        ours, chance = [], []
        for frame_id in checkpoint.test_frame_ids:
            frame = db.session.get(Frame, frame_id)
            truth = ground_truth.mask_of(ground_truth.ground_truths([frame_id])[frame_id])
            s = labelling.suggest_frame(frame, user(), version=0)
            assert s.proposer.held_out and s.prediction == "stored"
            union = np.zeros_like(truth)
            for instance in s.annotation.instances if s.annotation is not None else []:
                union |= saved_mask(instance)
            ours.append(iou(union, truth))
            chance.append(random_box_iou(truth, rng))
    print(f"held-out IoU: suggest median {np.median(ours):.3f} mean {np.mean(ours):.3f}; random box mean {np.mean(chance):.3f}")
    assert np.mean(ours) > max(0.2, 2.5 * np.mean(chance))


# --------------------------------------------------------------------------- Auto by evidence; no claim


def test_auto_chooses_by_evidence_not_by_order(app, annotator):
    """A run trained on the demo's rendered frames is Auto's on rendered frames only; a real frame with depth
    gets depth, unless the run has scored well on held-out real frames."""
    real, _ = held_bag(app)  # a frame imported by a person: real, with depth
    with app.app_context():
        create_demo(frames_per_activity=2, width=64, height=48)
        rendered = db.session.execute(db.select(Frame).join(Frame.sequence).join(Activity)
                                      .where(Activity.name == "cooking")).scalars().first()
        run_id = stored_run({rendered.id: network_like(np.ones((48, 64), bool))}, activities=("cooking",), name="demo run")
        frame = db.session.get(Frame, real)
        assert proposers.frame_kind(frame) == "real" and proposers.frame_kind(rendered) == "rendered"
        assert proposers.auto_choice(frame) == (None, "depth", "this frame has depth")
        runs = [c for c in labelling.source_choices(frame)["choices"] if c["source"] == "model"]
        assert runs == [{"source": "model", "run_id": run_id, "disabled": False,  # offered, with what it learnt from
                         "label": f"Run {run_id}: demo run — trained on the demo's rendered frames"}]
        run, source, reason = proposers.auto_choice(rendered)
        assert (run.id, source, reason) == (run_id, "model", "trained on the demo's rendered frames like this one")

        # Depth predicted from the image is weaker evidence, and the reason says so.
        frame.meta = {"depth_source": "predicted"}
        db.session.commit()
        assert proposers.auto_choice(frame)[2].startswith("this frame has depth, predicted from its image")

        # Measured: the run's held-out predictions of real frames score F 0.6 (stored as scoring stores them).
        db.session.add(Prediction(run_id=run_id, checkpoint_id=db.session.get(TrainingRun, run_id).checkpoints[0].id,
                                  frame_id=real, held_out=True, f_score=0.6,
                                  path=media.store(io.encode_probability_png(np.zeros((240, 320), np.float32)), ".png")))
        db.session.commit()
        run, source, reason = proposers.auto_choice(frame)
        assert (run.id, source, reason) == (run_id, "model", "scores F 0.60 on 1 held-out real frames")
    response = annotator.post(f"/api/label/frames/{real}/suggest", json={"version": 0})
    assert response.get_json()["suggestion"]["message"].startswith(f"Run {run_id}: scores F 0.60 on 1 held-out real frames.")
    for forbidden in ("fold", "threshold", "single"):
        assert forbidden not in response.get_json()["suggestion"]["message"]


def test_on_the_real_chair_auto_passes_over_the_demo_run_and_depth_finds_the_chair(app, annotator):
    """rgbd-primesense 00001 (real RGB-D), with a run trained on the demo: Auto is depth, which finds the chair."""
    from tests.realdata import PRIMESENSE, chair_truth

    if not PRIMESENSE.exists():
        pytest.skip("../shared/data/rgbd-primesense is absent")
    with app.app_context():
        create_demo(frames_per_activity=1, width=64, height=48)
        run_id = stored_run({}, activities=("cooking",), name="demo quick start")
        K = io.read_intrinsics(PRIMESENSE / "camera_primesense.json")
        add_frames(activity="room", sequence="s1", items=[FrameItem(
            "00001", 0, "00001", rgb=io.read_image(PRIMESENSE / "color" / "00001.jpg"),
            depth_m=io.read_depth(PRIMESENSE / "depth" / "00001.png"), K=K)])
        frame_id = db.session.execute(db.select(Frame.id).where(Frame.source_name == "00001")).scalar_one()
    page = annotator.get(f"/label/frames/{frame_id}").get_data(as_text=True)
    assert "Auto uses depth: this frame has depth. Run" in page and "No trained run yet" not in page
    response = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0})
    s = response.get_json()["suggestion"]
    assert s["source"] == "depth" and s["message"].startswith("Depth: this frame has depth. It proposed 1 object")
    with app.app_context():
        best = max(iou(saved_mask(i), chair_truth()) for i in own_annotation(frame_id).instances)
    assert best > 0.8  # measured 0.86; the demo's run proposed nothing here (docs/labelling.md)
    assert s["run_id"] is None and run_id in [c["run_id"] for c in labelling_choices(app, frame_id)]


def test_rgb_only_real_frames_get_object_sized_proposals(app, annotator):
    """The authors' real frames without their DHG: Auto is handled, every proposal under 6 % of the frame
    (one region was 21-27 % before the seam between regions)."""
    from tests.realdata import EGONET_SAMPLES

    if not EGONET_SAMPLES.exists():
        pytest.skip("../shared/data/egonet-samples is absent")
    name = "02_024150_3"  # the frame whose one proposal covered 24 % of it
    with app.app_context():
        add_frames(activity="kitchen", sequence="s1",
                   items=[FrameItem(name, 0, name, rgb=io.read_image(EGONET_SAMPLES / "rgb" / f"{name}.jpg"))])
        frame_id = db.session.execute(db.select(Frame.id).where(Frame.source_name == name)).scalar_one()
        stored_run({}, activities=("kitchen",))  # trained on these frames, but it reads DHG, which they lack
        choices = labelling.source_choices(db.session.get(Frame, frame_id))
    assert choices["choices"][0]["label"] == "Auto (handled)" and choices["choices"][-1]["disabled"]
    s = annotator.post(f"/api/label/frames/{frame_id}/suggest", json={"version": 0}).get_json()["suggestion"]
    assert s["source"] == "handled" and len(s["proposals"]) >= 1
    with app.app_context():
        shares = [saved_mask(i).mean() for i in own_annotation(frame_id).instances]
    assert max(shares) < 0.06, shares  # measured 0.053 at most


def test_suggest_claims_no_frame(app, client, make_user):
    """ann tries Suggest on every frame of an activity (proposals on one, none on the others): the frames stay
    to label for everyone, the Label page and the Activities page agree; accepting a proposal claims its frame."""
    ann, bob = make_user("annotator", "ann"), make_user("annotator", "bob")
    frames = make_frames(app, n=3)
    with app.app_context():
        stored_run({frames[0]: network_like(true_mask()), frames[1]: np.zeros((H, W), np.float32),
                    frames[2]: np.zeros((H, W), np.float32)})
        activity_id = db.session.execute(db.select(Activity.id).filter_by(name="kitchen")).scalar_one()
    client.login_as(ann)
    results = [client.post(f"/api/label/frames/{f}/suggest", json={"version": 0}).get_json() for f in frames]
    assert [len(r["suggestion"]["proposals"]) for r in results] == [1, 0, 0]
    assert results[1]["suggestion"]["message"] == (
        "Run 1: trained on real frames like this one. It found no object to propose here; choose another source, "
        "or draw a box (B).").replace("Run 1", f"Run {results[1]['suggestion']['run_id']}")
    assert results[0]["annotation"]["status"] == "todo" and results[1]["annotation"]["version"] == 0

    def label_counts():
        page = client.get("/label/").get_data(as_text=True)
        return page.count("<td>3</td>"), "<h2>In progress" in page

    def next_frame():
        return client.get(f"/label/next?activity={activity_id}").headers["Location"]

    for who in (ann, bob):
        client.login_as(who)
        assert next_frame().endswith(f"/label/frames/{frames[0]}")  # not "Nothing left to label here"
        assert "3 of 3 left to label" in client.get("/").get_data(as_text=True)  # the Activities page
        assert label_counts() == (2, False)  # Frames 3, To label 3; nothing listed in progress
    grid = client.get(f"/activities/{activity_id}").get_data(as_text=True)
    assert "status-in_progress" not in grid
    # bob opening the frame with ann's proposals hears of nobody holding it.
    others = client.post(f"/api/label/frames/{frames[0]}/presence", json={"open": False}).get_json()["others"]
    assert others == []

    # Accepting the proposal makes it ann's work: bob's next frame is another one, and the counts follow.
    client.login_as(ann)
    key = results[0]["suggestion"]["proposals"][0]
    accepted = client.post(f"/api/label/frames/{frames[0]}/annotation/proposals/accept",
                           json={"version": results[0]["annotation"]["version"], "key": key}).get_json()
    assert accepted["status"] == "in_progress"
    assert "<h2>In progress" in client.get("/label/").get_data(as_text=True)
    client.login_as(bob)
    assert next_frame().endswith(f"/label/frames/{frames[1]}")
    others = client.post(f"/api/label/frames/{frames[0]}/presence", json={"open": False}).get_json()["others"]
    assert [(o["username"], o["status"]) for o in others] == [("ann", "in_progress")]
    assert "<td>2</td>" in client.get("/label/").get_data(as_text=True)


def labelling_choices(app, frame_id: int) -> list[dict]:
    with app.app_context():
        return labelling.source_choices(db.session.get(Frame, frame_id))["choices"]
