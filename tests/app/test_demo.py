"""The demo leaves frames to label, the pages say how many, and the renderer still knows their truth."""

import re

import numpy as np
import pytest

from app.errors import Problem
from app.extensions import db
from app.models import HAND_LABEL, Activity, Frame, Sequence, User
from app.services import labelling, media
from app.services.demo import create_demo, renderer_truth, unlabelled_count
from app.services.ground_truth import ground_truths, labelled_frames, mask_of
from app.services.importing import import_path
from egonet import io, synth
from tests.app.conftest import PASSWORD
from tests.app.factories import image_folder

SIZE = {"width": 64, "height": 48}


def frames_of(activity: str) -> list[Frame]:
    query = db.select(Frame).join(Sequence).join(Activity).where(Activity.name == activity).order_by(Frame.index)
    return list(db.session.execute(query).scalars())


@pytest.mark.parametrize(
    ("frames", "fraction", "expected"),
    [
        (40, 0.25, 10),
        (6, 0.25, 2),  # 1.5 rounds up
        (5, 0.25, 1),  # 1.25 rounds down
        (3, 0.25, 1),
        (2, 0.25, 1),  # 0.5 rounds up (Python's round would give 0)
        (10, 0.01, 1),  # at least one when there are two frames or more
        (1, 0.25, 0),  # a lone frame stays labelled
        (40, 0.0, 0),
        (4, 1.0, 4),
    ],
)
def test_unlabelled_count(frames, fraction, expected):
    assert unlabelled_count(frames, fraction) == expected


def test_the_last_quarter_of_each_activity_is_left_unlabelled_and_the_renderer_still_knows_its_truth(ctx):
    reports = create_demo(frames_per_activity=4, seed=2, **SIZE)
    assert [(r.added, r.annotations) for r in reports] == [(4, 3)] * len(synth.ACTIVITIES)
    assert len(labelled_frames()) == 3 * len(synth.ACTIVITIES)
    for activity in synth.ACTIVITIES:
        frames = frames_of(activity)
        truths = ground_truths(f.id for f in frames)
        assert [f.index for f in frames if f.id in truths] == [0, 1, 2], activity
        last = frames[3]
        assert last.annotations == []
        truth = renderer_truth(last)
        assert truth.shape == (48, 64) and truth.dtype == bool and truth.any()
        np.testing.assert_array_equal(truth, synth.render_frame(activity, 3, seed=2, **SIZE).mask)
        # For a labelled frame it is the stored ground truth.
        np.testing.assert_array_equal(renderer_truth(frames[0]), mask_of(truths[frames[0].id]))


def test_the_demo_ships_hand_masks_that_are_no_part_of_the_action_object(ctx):
    create_demo(frames_per_activity=6, unlabelled_fraction=0.0, **SIZE)
    hands_seen = 0
    for frame in labelled_frames():
        annotation = ground_truths([frame.id])[frame.id]
        rendered = synth.render_frame(frame.meta["activity"], frame.meta["index"], seed=0, **SIZE)
        hands = [i for i in annotation.instances if i.label == HAND_LABEL]
        objects = [i for i in annotation.instances if i.label != HAND_LABEL]
        assert [i.label for i in objects] == [frame.meta["object"]]
        # The ground truth is the action-object alone, whatever the hands.
        np.testing.assert_array_equal(mask_of(annotation), rendered.mask)
        if rendered.hands.any():
            hands_seen += 1
            (hand,) = hands
            np.testing.assert_array_equal(io.read_mask(media.local_path(hand.mask_path)), rendered.hands)
            assert not (rendered.hands & rendered.mask).any()
        else:
            assert hands == []
    assert hands_seen >= 10  # most demo frames show a hand


def test_renderer_truth_refuses_frames_it_did_not_make(ctx, tmp_path):
    create_demo(frames_per_activity=1, **SIZE)
    import_path(image_folder(tmp_path / "rec", n=1), activity="cooking", sequence="take1")
    imported = db.session.execute(db.select(Frame).join(Sequence).filter(Sequence.name == "take1")).scalar_one()
    with pytest.raises(Problem, match="not a demo frame") as caught:
        renderer_truth(imported)
    assert caught.value.field == "frame"
    # A demo frame whose metadata no longer gives back its image (another seed here, as a changed renderer would).
    (demo_frame,) = frames_of("hotel")
    demo_frame.meta = {**demo_frame.meta, "seed": 99}
    with pytest.raises(Problem, match="no longer makes this image") as caught:
        renderer_truth(demo_frame)
    assert caught.value.field == "frame"


@pytest.mark.parametrize("bad", [-0.1, 1.01, float("nan")])
def test_a_bad_unlabelled_fraction_names_the_option_and_adds_nothing(ctx, bad):
    with pytest.raises(Problem, match="--unlabelled-fraction must be between 0 and 1") as caught:
        create_demo(frames_per_activity=2, unlabelled_fraction=bad, **SIZE)
    assert caught.value.field == "unlabelled_fraction"
    assert db.session.execute(db.select(Frame)).first() is None


def test_unlabelled_fraction_0_labels_everything(ctx):
    create_demo(frames_per_activity=3, unlabelled_fraction=0, **SIZE)
    assert len(labelled_frames()) == 3 * len(synth.ACTIVITIES)


def test_the_pages_say_how_many_are_left_and_next_unlabelled_finds_them(app, client, make_user):
    with app.app_context():
        create_demo(frames_per_activity=4, **SIZE)
        cooking, desk = frames_of("cooking"), frames_of("desk work")
        cooking_id = cooking[0].sequence.activity_id
        cooking_last, desk_last = cooking[3].id, desk[3].id
    annotator = make_user("annotator", "ann")
    assert client.login("ann", PASSWORD).status_code == 302

    index = client.get("/").get_data(as_text=True)
    assert index.count("1 of 4 left to label") == len(synth.ACTIVITIES)
    assert index.count('<progress class="progress" max="4" value="3"') == len(synth.ACTIVITIES)

    grid = client.get(f"/activities/{cooking_id}").get_data(as_text=True)
    assert "1 of 4 left to label" in grid and '<progress class="progress" max="4" value="3"' in grid
    tiles = re.findall(r'data-frame-id="(\d+)".*?class="status status-(\w+)"', grid, re.S)
    assert [status for _, status in tiles] == ["reviewed", "reviewed", "reviewed", "todo"]
    assert int(tiles[3][0]) == cooking_last
    link = re.search(r'id="label-next" href="([^"]+)"', grid).group(1).replace("&amp;", "&")
    assert client.get(link).location.endswith(f"/label/frames/{cooking_last}")
    # The Label page's "next unlabelled": the first one in dataset order (activities by name).
    assert client.get("/label/next").location.endswith(f"/label/frames/{cooking_last}")

    # Once it is done, the count drops and "next unlabelled" moves on.
    done = {"version": 0, "instances": [], "no_action_object": True, "status": "done", "time_spent_delta_s": 3}
    with app.app_context():
        labelling.save_annotation(db.session.get(Frame, cooking_last), db.session.get(User, annotator.id), done)
    grid = client.get(f"/activities/{cooking_id}").get_data(as_text=True)
    assert "all 4 labelled" in grid and "left to label" not in grid and 'id="label-next"' not in grid
    assert client.get("/").get_data(as_text=True).count("1 of 4 left to label") == len(synth.ACTIVITIES) - 1
    assert client.get("/label/next").location.endswith(f"/label/frames/{desk_last}")


def test_reviewers_see_the_count_but_no_labelling_link(app, client, make_user):
    with app.app_context():
        create_demo(frames_per_activity=2, **SIZE)
        activity_id = frames_of("hotel")[0].sequence.activity_id
    make_user("reviewer", "rev")
    assert client.login("rev", PASSWORD).status_code == 302
    grid = client.get(f"/activities/{activity_id}").get_data(as_text=True)
    assert "1 of 2 left to label" in grid and 'id="label-next"' not in grid
