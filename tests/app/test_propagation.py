"""Propagate to the next frame, copy from the previous one, the filmstrip:
through the API, on small RGB-D sequences of a moving object."""


import cv2
import numpy as np
import pytest

from app.extensions import db
from app.models import Activity, Frame, Sequence
from app.services import media
from app.services.importing import FrameItem, add_frames, import_path
from app.services.labelling import propagation
from egonet import io
from tests.app.test_labelling import get_png, rle
from tests.app.test_labelling_grabcut import call, forget_everything
from tests.realdata import PRIMESENSE

H, W = 120, 160
STEP = 4  # columns the object moves per frame
CUP = (slice(40, 80), slice(30, 70))  # rows, columns in frame 0
LID = (slice(20, 36), slice(110, 140))  # a second object, still


def cup_at(i: int) -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[CUP[0], CUP[1].start + STEP * i:CUP[1].stop + STEP * i] = True
    return mask


def lid() -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[LID] = True
    return mask


def moving_frames(app, n: int = 3, *, sequence: str = "s1", depth: bool = True, gone: tuple[int, ...] = (),
                  repeat: int = 3) -> list[int]:
    """A textured red cup sliding right over a green table (and a still blue lid), 0.6 m away on a 1.2 m table;
    on the frames in ``gone`` a hand has taken the cup away (the table shows where it was). The cup's
    motion repeats every ``repeat`` frames (long sequences, the filmstrip's, stay inside the frame)."""
    rng = np.random.default_rng(7)
    table = (rng.integers(0, 40, (H, W, 3)) + [40, 120, 50]).astype(np.uint8)
    cup = (rng.integers(0, 40, (40, 40, 3)) + [180, 30, 30]).astype(np.uint8)
    items = []
    for i in range(n):
        image = table.copy()
        if i not in gone:
            image[cup_at(i % repeat)] = cup.reshape(-1, 3)
        image[-1, -1] = i % 256  # ... each frame its own content
        image[LID] = (30, 40, 200)
        d = np.full((H, W), 1.2, np.float32)
        d[cup_at(i % repeat) | lid()] = 0.6
        items.append(FrameItem(f"{sequence}-{i:03d}", i, f"test {i}", rgb=image, depth_m=d if depth else None))
    with app.app_context():
        add_frames(activity="kitchen", sequence=sequence, items=items)
        query = db.select(Frame.id).join(Sequence).join(Activity).where(Sequence.name == sequence)
        return list(db.session.execute(query.order_by(Frame.index)).scalars())


def annotate(client, frame_id: int, *masks: np.ndarray, version: int = 0, **extra) -> dict:
    instances = [{"key": f"k{i}", "kind": "tactile" if i == 0 else None, "label": f"o{i}", "mask": rle(m)}
                 for i, m in enumerate(masks)]
    response = client.put(f"/api/label/frames/{frame_id}/annotation",
                          json={"version": version, "instances": instances, **extra})
    assert response.status_code == 200, response.data
    return response.get_json()


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


@pytest.fixture
def annotator(client, make_user):
    client.login_as(make_user("annotator", "ann"))
    return client


@pytest.mark.both_storages
def test_propagate_to_next_frame_makes_an_in_progress_annotation_that_follows_the_objects(app, annotator):
    f0, f1, _ = moving_frames(app)
    annotate(annotator, f0, cup_at(0), lid())

    response = annotator.post(f"/api/label/frames/{f0}/propagate", json={})
    assert response.status_code == 200, response.data
    new = response.get_json()
    assert new["frame_id"] == f1 and new["url"] == f"/label/frames/{f1}"
    assert new["status"] == "in_progress" and new["version"] == 1 and new["author"] == "ann"
    assert [(i["key"], i["kind"], i["label"]) for i in new["instances"]] == [("k0", "tactile", "o0"), ("k1", None, "o1")]
    cup, still = (get_png(annotator, i["mask_url"]) for i in new["instances"])
    # The masks moved with the objects: closer to where they are now than a plain copy would be.
    assert iou(cup, cup_at(1)) > 0.9 and iou(cup, cup_at(1)) > iou(cup_at(0), cup_at(1))
    assert iou(still, lid()) > 0.9
    assert (cup & cup_at(0)).any()  # overlapping the source's, the frames being alike
    # The page reads it as the user's annotation of the next frame.
    assert annotator.get(f"/api/label/frames/{f1}/annotation").get_json()["version"] == 1


def test_propagated_objects_take_strokes_at_once_without_a_box(app, annotator, monkeypatch):
    f0, f1, _ = moving_frames(app)
    annotate(annotator, f0, cup_at(0), lid())
    forget_everything(app, monkeypatch)  # every request restores sessions from the database
    new = annotator.post(f"/api/label/frames/{f0}/propagate", json={}).get_json()
    carried = get_png(annotator, new["instances"][0]["mask_url"])
    # Each carried object has a GrabCut session, which the page loads with the annotation ...
    assert annotator.get(f"/api/label/frames/{f1}/annotation").get_json()["grabcut"] == ["k0", "k1"]
    with annotator.get(f"/api/label/grabcut/mask.png?frame_id={f1}&instance=k0") as response:
        assert response.status_code == 200
        np.testing.assert_array_equal(io.decode_mask(response.data), carried)  # ... and it starts from the saved mask
    # A background stroke across the cup's middle, no box first: it takes the cup's pixels out there only.
    can_undo, mask = call(annotator, "stroke", frame_id=f1, instance="k0", points=[[50, 60], [70, 60]],
                          label="bg", radius=3)
    assert can_undo == "1" and not mask[60, 60] and (mask & carried == mask).all()
    assert mask.sum() > 0.8 * carried.sum()
    # An object stroke on the table beside the cup adds it, as after a box; undo goes back to the carried mask.
    _, mask = call(annotator, "stroke", frame_id=f1, instance="k0", points=[[30, 60]], label="fg", radius=3)
    assert mask[60, 30]
    call(annotator, "undo", frame_id=f1, instance="k0")
    _, mask = call(annotator, "undo", frame_id=f1, instance="k0")
    np.testing.assert_array_equal(mask, carried)


def test_copy_from_previous_frame_fills_this_frame(app, annotator):
    f0, f1, f2 = moving_frames(app)
    annotate(annotator, f1, cup_at(1))
    response = annotator.post(f"/api/label/frames/{f2}/copy-previous", json={})
    assert response.status_code == 200, response.data
    copied = response.get_json()
    assert copied["frame_id"] == f2 and copied["status"] == "in_progress" and len(copied["instances"]) == 1
    assert iou(get_png(annotator, copied["instances"][0]["mask_url"]), cup_at(2)) > 0.9
    # The first frame has nothing before it.
    first = annotator.post(f"/api/label/frames/{f0}/copy-previous", json={})
    assert first.status_code == 404 and "previous" in first.get_json()["fields"]


def test_existing_work_is_refused_with_409_and_replaced_only_explicitly_at_its_version(app, annotator):
    f0, f1, _ = moving_frames(app)
    annotate(annotator, f0, cup_at(0))
    mine = annotate(annotator, f1, lid())
    url = f"/api/label/frames/{f0}/propagate"

    refused = annotator.post(url, json={})
    assert refused.status_code == 409
    error = refused.get_json()
    assert "replace" in error["fields"] and error["current_version"] == mine["version"] and error["frame_id"] == f1
    kept = annotator.get(f"/api/label/frames/{f1}/annotation").get_json()
    assert kept["version"] == mine["version"] and np.array_equal(get_png(annotator, kept["instances"][0]["mask_url"]), lid())

    # replace goes through the normal version check: none or an old one is stale.
    for stale in ({"replace": True}, {"replace": True, "version": mine["version"] - 1}):
        answer = annotator.post(url, json=stale)
        assert answer.status_code == 409 and "version" in answer.get_json()["fields"]
    replaced = annotator.post(url, json={"replace": True, "version": mine["version"]})
    assert replaced.status_code == 200, replaced.data
    body = replaced.get_json()
    assert body["version"] == mine["version"] + 1 and body["status"] == "in_progress"
    assert iou(get_png(annotator, body["instances"][0]["mask_url"]), cup_at(1)) > 0.9


def test_a_finished_annotation_or_no_action_object_is_not_overwritten(app, annotator):
    f0, f1, f2 = moving_frames(app)
    annotate(annotator, f0, cup_at(0))
    done = annotate(annotator, f1, cup_at(1), status="done")
    for request in ({}, {"replace": True, "version": done["version"]}):
        answer = annotator.post(f"/api/label/frames/{f0}/propagate", json=request)
        assert answer.status_code == 409 and "status" in answer.get_json()["fields"]
    assert annotator.get(f"/api/label/frames/{f1}/annotation").get_json()["status"] == "done"

    empty = annotate(annotator, f2, no_action_object=True)
    answer = annotator.post(f"/api/label/frames/{f2}/copy-previous", json={})
    assert answer.status_code == 409 and "replace" in answer.get_json()["fields"]
    replaced = annotator.post(f"/api/label/frames/{f2}/copy-previous", json={"replace": True, "version": empty["version"]})
    assert replaced.status_code == 200 and not replaced.get_json()["no_action_object"]


def test_an_empty_in_progress_annotation_is_no_work_to_protect(app, annotator):
    f0, f1, _ = moving_frames(app)
    annotate(annotator, f0, cup_at(0))
    blank = annotate(annotator, f1)  # saved, nothing drawn
    answer = annotator.post(f"/api/label/frames/{f0}/propagate", json={})
    assert answer.status_code == 200 and answer.get_json()["version"] == blank["version"] + 1


def test_no_next_frame_nothing_drawn_and_sequence_boundaries(app, annotator):
    first = moving_frames(app, 2, sequence="s1")
    second = moving_frames(app, 2, sequence="s2")
    annotate(annotator, first[1], cup_at(1))
    # The last frame of s1 has no next frame, though s2's frames come after it.
    last = annotator.post(f"/api/label/frames/{first[1]}/propagate", json={})
    assert last.status_code == 404 and "next" in last.get_json()["fields"]
    copy = annotator.post(f"/api/label/frames/{second[0]}/copy-previous", json={})
    assert copy.status_code == 404 and "previous" in copy.get_json()["fields"]
    # Nothing drawn on the source frame: nothing to carry.
    nothing = annotator.post(f"/api/label/frames/{second[0]}/propagate", json={})
    assert nothing.status_code == 404 and "frame_id" in nothing.get_json()["fields"]
    unknown = annotator.post("/api/label/frames/999999/propagate", json={})
    assert unknown.status_code == 404
    bad = annotator.post(f"/api/label/frames/{first[0]}/propagate", json={"replace": "yes"})
    assert bad.status_code == 400 and "replace" in bad.get_json()["fields"]


def test_stored_depth_goes_to_the_engine_when_both_frames_have_it(app, annotator, monkeypatch):
    seen = []
    real = propagation.carry_mask

    def spy(prev_rgb, prev_mask, next_rgb, *, prev_depth=None, next_depth=None):
        seen.append((prev_depth, next_depth))
        return real(prev_rgb, prev_mask, next_rgb, prev_depth=prev_depth, next_depth=next_depth)

    monkeypatch.setattr(propagation, "carry_mask", spy)
    with_depth = moving_frames(app, 2, sequence="rgbd")
    without = moving_frames(app, 2, sequence="rgb", depth=False)
    for f0, _ in (with_depth, without):
        annotate(annotator, f0, cup_at(0))
        assert annotator.post(f"/api/label/frames/{f0}/propagate", json={}).status_code == 200
    (prev_d, next_d), (none_a, none_b) = seen
    assert prev_d.shape == (H, W) and prev_d.dtype == np.float32
    assert prev_d[cup_at(0)].mean() == pytest.approx(0.6, abs=0.01) and next_d[cup_at(1)].mean() == pytest.approx(0.6, abs=0.01)
    assert none_a is None and none_b is None


def test_only_labellers_propagate(app, client, make_user):
    f0, _ = moving_frames(app, 2)
    client.login_as(make_user("reviewer", "rev"))
    assert client.post(f"/api/label/frames/{f0}/propagate", json={}).status_code == 403
    assert client.get(f"/api/label/frames/{f0}/filmstrip").status_code == 403


def test_the_filmstrip_is_a_window_of_the_sequence_with_statuses(app, annotator):
    ids = moving_frames(app, 30, depth=False)
    annotate(annotator, ids[15], cup_at(0), status="done")
    annotate(annotator, ids[16], cup_at(0))

    strip = annotator.get(f"/api/label/frames/{ids[15]}/filmstrip?count=11").get_json()
    assert strip["total"] == 30 and strip["start"] == 10 and strip["focus"]["id"] == ids[15]
    assert strip["focus"]["position"] == 15
    assert [f["id"] for f in strip["frames"]] == ids[10:21]
    statuses = {f["id"]: f["status"] for f in strip["frames"]}
    assert statuses[ids[15]] == "done" and statuses[ids[16]] == "in_progress" and statuses[ids[14]] == "todo"
    assert strip["frames"][0]["thumb_url"] == f"/frames/{ids[10]}/thumb.jpg"
    with annotator.get(strip["frames"][0]["thumb_url"]) as thumb:
        assert thumb.status_code == 200 and thumb.mimetype == "image/jpeg"

    # Near the ends the window stays full; "start" pages it; "at" finds a frame by its number.
    assert [f["id"] for f in annotator.get(f"/api/label/frames/{ids[1]}/filmstrip?count=11").get_json()["frames"]] == ids[:11]
    assert annotator.get(f"/api/label/frames/{ids[1]}/filmstrip?count=5&start=27").get_json()["start"] == 25
    jump = annotator.get(f"/api/label/frames/{ids[1]}/filmstrip?count=5&at=22").get_json()
    assert jump["focus"] == {"id": ids[22], "index": 22, "position": 22, "url": f"/label/frames/{ids[22]}"}
    missing = annotator.get(f"/api/label/frames/{ids[1]}/filmstrip?at=300")
    assert missing.status_code == 404 and "at" in missing.get_json()["fields"]
    too_many = annotator.get(f"/api/label/frames/{ids[1]}/filmstrip?count=5000")
    assert too_many.status_code == 400 and "count" in too_many.get_json()["fields"]




def chair_from_depth(depth: np.ndarray) -> np.ndarray:
    """The chair of the PrimeSense room frames from depth alone: what stands
    4 cm or more in front of the wall's plane, inside a fixed box (so the
    reference shares none of propagation's colour cues)."""
    fx = fy = 525.0
    cx, cy = 319.5, 239.5
    v, u = np.mgrid[0:480, 0:640]
    pts = np.stack([(u - cx) / fx * depth, (v - cy) / fy * depth, depth], -1)
    wall = pts[20:100, 300:600].reshape(-1, 3)
    centre = wall.mean(0)
    normal = np.linalg.svd(wall - centre, full_matrices=False)[2][2]
    normal = -normal if normal[2] > 0 else normal
    chair = (depth > 0) & ((pts - centre) @ normal > 0.04)
    chair[:90], chair[300:], chair[:, :320], chair[:, 615:] = False, False, False, False
    n, labels, stats, _ = cv2.connectedComponentsWithStats(chair.view(np.uint8))
    return labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))


@pytest.mark.skipif(not PRIMESENSE.exists(), reason="shared data not present")
def test_real_rgbd_frames_propagate_the_chair_with_their_stored_depth(app, annotator):
    with app.app_context():
        import_path(PRIMESENSE, activity="room")
        frames = list(db.session.execute(db.select(Frame).order_by(Frame.index)).scalars())
        assert all(f.depth_path for f in frames)
        chairs = [chair_from_depth(io.read_depth(media.local_path(f.depth_path))) for f in frames[:2]]
        f0, f1 = frames[0].id, frames[1].id
    annotate(annotator, f0, chairs[0])
    response = annotator.post(f"/api/label/frames/{f0}/propagate", json={})
    assert response.status_code == 200, response.data
    carried = get_png(annotator, response.get_json()["instances"][0]["mask_url"])
    assert iou(carried, chairs[1]) > 0.9 and iou(carried, chairs[1]) > iou(chairs[0], chairs[1])


# ------------------------------------------------------------------ both ways, over a range


def carried_mask(client, frame_id: int, key: str = "k0") -> np.ndarray:
    annotation = client.get(f"/api/label/frames/{frame_id}/annotation").get_json()
    return get_png(client, next(i for i in annotation["instances"] if i["key"] == key)["mask_url"])


def test_propagate_to_the_previous_frame_carries_backwards(app, annotator):
    f0, f1, f2 = moving_frames(app)
    annotate(annotator, f2, cup_at(2), lid())
    response = annotator.post(f"/api/label/frames/{f2}/propagate", json={"direction": "previous"})
    assert response.status_code == 200, response.data
    body = response.get_json()
    assert body["frame_id"] == f1 and body["url"] == f"/label/frames/{f1}" and body["status"] == "in_progress"
    assert body["carried"] == [{"frame_id": f1, "index": 1}] and body["stopped"] is None
    cup = carried_mask(annotator, f1)
    assert iou(cup, cup_at(1)) > 0.9 and iou(cup, cup_at(1)) > iou(cup_at(2), cup_at(1))
    # The first frame has no previous one.
    annotate(annotator, f0, cup_at(0))
    response = annotator.post(f"/api/label/frames/{f0}/propagate", json={"direction": "previous"})
    assert response.status_code == 404 and "previous" in response.get_json()["fields"]


def test_a_range_carries_frame_after_frame_each_its_own_version(app, annotator):
    ids = moving_frames(app, 6, depth=False, repeat=6)
    annotate(annotator, ids[0], cup_at(0), lid())
    response = annotator.post(f"/api/label/frames/{ids[0]}/propagate", json={"count": 4})
    assert response.status_code == 200, response.data
    body = response.get_json()
    assert body["carried"] == [{"frame_id": ids[i], "index": i} for i in (1, 2, 3, 4)]
    assert body["stopped"] is None and body["frame_id"] == ids[4]
    for i in (1, 2, 3, 4):
        annotation = annotator.get(f"/api/label/frames/{ids[i]}/annotation").get_json()
        # Each frame is its own in-progress annotation at version 1, its objects with GrabCut sessions.
        assert (annotation["status"], annotation["version"], annotation["grabcut"]) == ("in_progress", 1, ["k0", "k1"])
        assert iou(carried_mask(annotator, ids[i]), cup_at(i)) > 0.85, i
    assert annotator.get(f"/api/label/frames/{ids[5]}/annotation").get_json()["version"] == 0
    # Backwards onto the carried work: the first target is asked about as for one frame (409, replace).
    annotate(annotator, ids[5], cup_at(5), lid())
    response = annotator.post(f"/api/label/frames/{ids[5]}/propagate", json={"direction": "previous", "count": 3})
    assert response.status_code == 409 and "replace" in response.get_json()["fields"]
    assert response.get_json()["frame_id"] == ids[4]


def test_a_range_stops_before_work_and_at_the_sequence_end_and_says_so(app, annotator):
    ids = moving_frames(app, 5, depth=False, repeat=5)
    annotate(annotator, ids[0], cup_at(0))
    kept = annotate(annotator, ids[3], lid(), status="done")
    body = annotator.post(f"/api/label/frames/{ids[0]}/propagate", json={"count": 4}).get_json()
    assert [c["frame_id"] for c in body["carried"]] == [ids[1], ids[2]]
    assert body["stopped"] == {"kind": "work", "frame_id": ids[3], "index": 3,
                               "reason": "stopped before frame #3: it already has your annotation (done)"}
    after = annotator.get(f"/api/label/frames/{ids[3]}/annotation").get_json()
    assert (after["version"], after["status"]) == (kept["version"], "done")  # left as it was
    # From frame 3 on to the end: two frames, then the sequence ends.
    body = annotator.post(f"/api/label/frames/{ids[3]}/propagate", json={"count": 5}).get_json()
    assert [c["index"] for c in body["carried"]] == [4]
    assert body["stopped"]["kind"] == "end" and body["stopped"]["reason"] == "frame #4 is the last of its sequence"


def test_a_range_stops_at_the_first_unsure_frame_and_says_which(app, annotator):
    # On frame 3 the cup is gone (taken out of view): the carried mask there is unsure.
    ids = moving_frames(app, 6, depth=False, gone=(3,), repeat=6)
    annotate(annotator, ids[0], cup_at(0))
    body = annotator.post(f"/api/label/frames/{ids[0]}/propagate", json={"count": 5}).get_json()
    assert [c["index"] for c in body["carried"]] == [1, 2, 3]
    stopped = body["stopped"]
    assert (stopped["kind"], stopped["frame_id"], stopped["index"]) == ("unsure", ids[3], 3)
    assert stopped["reason"].startswith("stopped at frame #3: the result looks unsure (object 1 (o0) "), stopped
    # The unsure frame is saved (the annotator lands on it to fix it); nothing beyond it is touched.
    assert body["frame_id"] == ids[3] and body["url"] == f"/label/frames/{ids[3]}"
    assert annotator.get(f"/api/label/frames/{ids[4]}/annotation").get_json()["version"] == 0


@pytest.mark.parametrize("body, field", [
    ({"count": 0}, "count"), ({"count": 11}, "count"), ({"count": "3"}, "count"),
    ({"direction": "up"}, "direction"),
])
def test_range_bounds_are_clear_errors(app, annotator, body, field):
    f0, _, _ = moving_frames(app)
    annotate(annotator, f0, cup_at(0))
    response = annotator.post(f"/api/label/frames/{f0}/propagate", json=body)
    assert response.status_code == 400 and field in response.get_json()["fields"], response.data


def test_many_objects_carry_to_fewer_frames_a_request(app, annotator):
    f0, f1, _ = moving_frames(app)
    annotate(annotator, f0, *[lid()] * 6)  # 6 objects: at most 8 frames a request (50 objects times frames)
    response = annotator.post(f"/api/label/frames/{f0}/propagate", json={"count": 9})
    assert response.status_code == 400
    assert response.get_json()["fields"] == {"count": "at most 8 with 6 objects"}
    assert annotator.get(f"/api/label/frames/{f1}/annotation").get_json()["version"] == 0  # nothing carried
