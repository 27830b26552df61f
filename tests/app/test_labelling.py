"""The labelling API: saving with a version check, statuses, review, the queue, masks."""

import re

import numpy as np
import pycocotools.mask as coco_mask
import pytest

from app.extensions import db
from app.models import Activity, Annotation, Frame, Sequence, Status, User
from app.services import labelling
from app.services.importing import FrameItem, add_frames
from egonet import io

H, W = 120, 160
OBJECT = (slice(40, 80), slice(50, 110))  # rows, columns of the red object


def make_frames(app, n: int = 3, activity: str = "kitchen") -> list[int]:
    """Frames of a red rectangle on a noisy green background (each slightly different)."""
    rng = np.random.default_rng(len(activity))
    items = []
    for i in range(n):
        image = (rng.integers(0, 30, (H, W, 3)) + [40, 130, 50]).astype(np.uint8)
        image[OBJECT] = (rng.integers(0, 30, (40, 60, 3)) + [190, 40, 40]).astype(np.uint8)
        items.append(FrameItem(f"f{i:03d}", i, f"test {i}", rgb=image))
    with app.app_context():
        add_frames(activity=activity, sequence="s1", items=items)
        query = db.select(Frame.id).join(Sequence).join(Activity).where(Activity.name == activity)
        return list(db.session.execute(query.order_by(Frame.index)).scalars())


def true_mask() -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[OBJECT] = True
    return mask


def rle(mask: np.ndarray) -> dict:
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in encoded["size"]], "counts": encoded["counts"].decode()}


def square(y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[y0:y1, x0:x1] = True
    return mask


def body(version: int, *masks: np.ndarray, **extra) -> dict:
    return {
        "version": version,
        "instances": [{"key": f"k{i}", "kind": None, "label": None, "mask": rle(m)} for i, m in enumerate(masks)],
        **extra,
    }


def get_png(client, url: str) -> np.ndarray:
    with client.get(url) as response:
        assert response.status_code == 200, response.data
        assert response.mimetype == "image/png"
        return io.decode_mask(response.data)


@pytest.fixture
def annotator(client, make_user):
    user = make_user("annotator", "ann")
    client.login_as(user)
    return client


def test_a_blank_annotation_then_a_save_and_its_masks(app, annotator):
    frame_id, *_ = make_frames(app)
    url = f"/api/label/frames/{frame_id}/annotation"
    blank = annotator.get(url).get_json()
    assert blank["version"] == 0 and blank["status"] == "todo" and blank["instances"] == [] and blank["grabcut"] == []
    assert (blank["width"], blank["height"]) == (W, H)

    a, b = square(10, 30, 10, 40), square(50, 90, 100, 150)
    request = body(0, a, b)
    request["instances"][0].update(kind="tactile", label="cup")
    saved = annotator.put(url, json=request).get_json()
    assert saved["version"] == 1 and saved["status"] == "in_progress" and saved["author"] == "ann"
    assert [(i["key"], i["kind"], i["label"]) for i in saved["instances"]] == [("k0", "tactile", "cup"), ("k1", None, None)]
    assert np.array_equal(get_png(annotator, saved["instances"][0]["mask_url"]), a)
    assert np.array_equal(get_png(annotator, saved["instances"][1]["mask_url"]), b)
    assert np.array_equal(get_png(annotator, saved["mask_url"]), a | b)
    assert annotator.get(url).get_json()["version"] == 1

    # Deleting an instance and saving again moves the version on by one; positions close up.
    again = annotator.put(url, json=body(1, b)).get_json()
    assert again["version"] == 2 and [i["position"] for i in again["instances"]] == [0]
    assert np.array_equal(get_png(annotator, again["instances"][0]["mask_url"]), b)


def test_a_stale_save_from_a_second_client_gets_409_and_changes_nothing(app, client, make_user):
    frame_id, *_ = make_frames(app)
    user = make_user("annotator", "ann")
    first, second = app.test_client(), app.test_client()
    first.login_as(user)
    second.login_as(user)
    url = f"/api/label/frames/{frame_id}/annotation"
    assert first.put(url, json=body(0, square(0, 10, 0, 10))).status_code == 200
    v1 = second.get(url).get_json()["version"]
    assert first.put(url, json=body(v1, square(0, 20, 0, 20))).get_json()["version"] == v1 + 1

    stale = second.put(url, json=body(v1, square(50, 60, 50, 60)))
    assert stale.status_code == 409
    error = stale.get_json()
    assert error["error"] == "conflict" and error["current_version"] == v1 + 1 and "version" in error["fields"]
    latest = second.get(url).get_json()
    assert latest["version"] == v1 + 1
    assert np.array_equal(get_png(second, latest["instances"][0]["mask_url"]), square(0, 20, 0, 20))

    # Creating when one exists is stale too; with the current version the save goes through.
    assert second.put(url, json=body(0, square(1, 2, 1, 2))).status_code == 409
    assert second.put(url, json=body(v1 + 1, square(50, 60, 50, 60))).status_code == 200


def test_statuses_no_action_object_and_time_spent(app, annotator):
    frame_id, *_ = make_frames(app)
    url = f"/api/label/frames/{frame_id}/annotation"
    nothing = annotator.put(url, json=body(0, status="done"))
    assert nothing.status_code == 400 and "status" in nothing.get_json()["fields"]
    v = annotator.put(url, json=body(0, time_spent_delta_s=12.5)).get_json()["version"]
    empty = annotator.put(url, json=body(v, np.zeros((H, W), bool), status="done"))
    assert empty.status_code == 400 and "instances[0].mask" in empty.get_json()["fields"]
    both = annotator.put(url, json=body(v, square(0, 5, 0, 5), no_action_object=True))
    assert both.status_code == 400 and "no_action_object" in both.get_json()["fields"]

    done = annotator.put(url, json=body(v, no_action_object=True, status="done", time_spent_delta_s=7.5)).get_json()
    assert done["status"] == "done" and done["no_action_object"] and done["mask_url"] is None
    assert done["time_spent_s"] == pytest.approx(20.0)
    # A done annotation is read-only: any save is refused until it is reopened, and costs nothing.
    for attempt in (body(done["version"], no_action_object=True), body(done["version"], square(0, 5, 0, 5))):
        refused = annotator.put(url, json=attempt)
        assert refused.status_code == 409, refused.get_json()
        error = refused.get_json()
        assert error["reason"] == "finished" and "reopen it" in error["message"] and "status" in error["fields"]
    reopen_url = f"{url}/reopen"
    assert annotator.post(reopen_url, json={"version": done["version"] - 1}).status_code == 409
    reopened = annotator.post(reopen_url, json={"version": done["version"]}).get_json()
    assert reopened["status"] == "in_progress" and reopened["version"] == done["version"] + 1
    assert annotator.post(reopen_url, json={"version": reopened["version"]}).get_json()["version"] == reopened["version"]
    edited = annotator.put(url, json=body(reopened["version"], square(0, 5, 0, 5))).get_json()
    assert edited["status"] == "in_progress" and edited["time_spent_s"] == pytest.approx(20.0)
    reopened = edited
    # Time alone (sent when the page is hidden) adds up without a new version.
    time_url = f"{url}/time"
    assert annotator.post(time_url, json={"seconds": 4}).status_code == 204
    assert annotator.post(time_url, json={"seconds": -4}).get_json()["fields"] == {"seconds": "must be >= 0"}
    after = annotator.get(url).get_json()
    assert after["version"] == reopened["version"] and after["time_spent_s"] == pytest.approx(24.0)
    other_frame = make_frames(app, n=1, activity="hotel")[0]
    assert annotator.post(f"/api/label/frames/{other_frame}/annotation/time", json={"seconds": 1}).status_code == 404
    with app.app_context():
        annotation = db.session.execute(db.select(Annotation)).scalar_one()
        assert annotation.mask_path is not None and annotation.time_spent_s == pytest.approx(24.0)


def broken_counts(change):
    def apply(b):
        mask = b["instances"][0]["mask"]
        mask["counts"] = change(mask["counts"])

    return apply


BAD_SAVES = [
    (lambda b: b.update(version=-1), "version"),
    (lambda b: b.pop("version"), "version"),
    (lambda b: b.update(status="reviewed"), "status"),
    (lambda b: b.update(time_spent_delta_s=-1), "time_spent_delta_s"),
    (lambda b: b.update(time_spent_delta_s=1e9), "time_spent_delta_s"),
    (lambda b: b.update(extra=1), "extra"),
    (lambda b: b["instances"][0].update(kind="edible"), "instances[0].kind"),
    (lambda b: b["instances"][0].update(key="no spaces"), "instances[0].key"),
    (lambda b: b["instances"][1].update(key="k0"), "instances[1].key"),
    (lambda b: b["instances"][0].update(mask={"size": [H, W]}), "instances[0].mask"),
    (lambda b: b["instances"][0].update(mask={"size": [H, W], "counts": 5}), "instances[0].mask"),
    (lambda b: b["instances"][0]["mask"].update(size=[W, H]), "instances[0].mask.size"),
    (lambda b: b["instances"][0]["mask"].update(counts=[5, 5]), "instances[0].mask.counts"),
    (lambda b: b["instances"][0]["mask"].update(counts="\u00ff"), "instances[0].mask.counts"),
    (lambda b: b["instances"][0]["mask"].update(counts=[H * W - 1, 2]), "instances[0].mask.counts"),
    (lambda b: b["instances"][0]["mask"].update(counts=[H * W + 1, -1]), "instances[0].mask.counts"),
    (lambda b: b["instances"][0]["mask"].update(counts=[H * W, True]), "instances[0].mask.counts"),
    (lambda b: b["instances"][0]["mask"].update(counts=[0] * (H * W + 2)), "instances[0].mask.counts"),
    # The first instance's counts string, broken: ends inside a number, a negative run, one run too many, too short.
    (broken_counts(lambda c: c + "P"), "instances[0].mask.counts"),
    (broken_counts(lambda c: "@" + c[1:]), "instances[0].mask.counts"),
    (broken_counts(lambda c: c + "1"), "instances[0].mask.counts"),
    (broken_counts(lambda c: c[:-1]), "instances[0].mask.counts"),
    (lambda b: b["instances"][0]["mask"].update(counts="1" * (H * W + 2)), "instances[0].mask.counts"),
]


def test_bad_save_bodies_are_400_naming_the_field(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    for change, field in BAD_SAVES:
        request = body(0, square(0, 5, 0, 5), square(5, 9, 5, 9))
        change(request)
        response = annotator.put(f"/api/label/frames/{frame_id}/annotation", json=request)
        assert response.status_code == 400, (field, response.get_json())
        assert field in response.get_json()["fields"], response.get_json()
    assert annotator.get(f"/api/label/frames/{frame_id}/annotation").get_json()["version"] == 0


def test_uncompressed_rle_counts_are_accepted(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    mask = square(3, 7, 11, 13)
    request = {"version": 0, "instances": [{"key": "a", "mask": {"size": [H, W], "counts": column_runs(mask)}}]}
    saved = annotator.put(f"/api/label/frames/{frame_id}/annotation", json=request).get_json()
    assert np.array_equal(get_png(annotator, saved["instances"][0]["mask_url"]), mask)


def column_runs(mask: np.ndarray) -> list[int]:
    """COCO's run lengths (down the columns, starting with background), counted by hand."""
    runs, value, run = [], False, 0
    for v in mask.T.ravel():
        if v != value:
            runs.append(run)
            run, value = 0, v
        run += 1
    return runs + [run]


def test_rle_decoder_agrees_with_pycocotools_and_the_length_bound_holds():
    rng = np.random.default_rng(3)
    masks = [rng.random((h, w)) < rng.random() for h, w in rng.integers(1, 40, (40, 2))]
    # The longest strings: every run one pixel, and runs alternating short and long.
    masks.append(np.indices((37, 23)).sum(axis=0) % 2 == 1)
    masks.append(np.resize(np.repeat([False, True, False, True], [1, 1, 40, 3]), (45, 41)))
    for mask in masks:
        h, w = mask.shape
        string = rle(mask)["counts"]
        assert len(string) <= labelling.max_rle_chars(h * w)
        for counts in (string, column_runs(mask)):
            decoded = labelling.decode_rle({"size": [h, w], "counts": counts}, (h, w), field="m")
            assert decoded.dtype == bool and decoded.flags.c_contiguous and np.array_equal(decoded, mask)


def test_png_upload_of_an_instance_mask(app, annotator, make_user):
    frame_id, *_ = make_frames(app, n=1)
    saved = annotator.put(f"/api/label/frames/{frame_id}/annotation", json=body(0, square(0, 5, 0, 5))).get_json()
    url = f"/api/label/annotations/{saved['id']}/instances/0/mask.png"
    new = square(20, 40, 20, 60)

    def put(data, version=saved["version"], path=url, mimetype="image/png"):
        query = f"?version={version}" if version is not None else ""
        return annotator.put(path + query, data=data, content_type=mimetype)

    assert put(io.encode_png(np.zeros((H, W + 1), bool))).get_json()["fields"].keys() == {"mask"}
    grey = np.full((H, W), 7, np.uint8)
    grey[0, 0] = 200
    response = put(io.encode_png(grey))
    assert response.status_code == 400 and "binary" in response.get_json()["fields"]["mask"]
    assert put(b"not a png").status_code == 400
    assert put(io.encode_png(new), version=None).get_json()["fields"] == {"version": "is required"}
    assert put(io.encode_png(new), mimetype="text/plain").status_code == 415
    assert put(io.encode_png(new), version=99).status_code == 409
    assert put(io.encode_png(new), path=url.replace("/0/", "/5/")).status_code == 404

    updated = put(io.encode_png(new)).get_json()
    assert updated["version"] == saved["version"] + 1 and updated["instances"][0]["key"] == "k0"
    assert np.array_equal(get_png(annotator, url), new)
    added = put(io.encode_png(square(0, 3, 0, 3)), version=updated["version"], path=url.replace("/0/", "/1/")).get_json()
    assert len(added["instances"]) == 2

    other = app.test_client()
    other.login_as(make_user("annotator", "someone-else"))
    response = other.put(url + f"?version={added['version']}", data=io.encode_png(new), content_type="image/png")
    assert response.status_code == 403


def test_review_accept_and_reject_with_a_comment(app, annotator, make_user):
    frame_id, second_id, _ = make_frames(app)
    url = f"/api/label/frames/{frame_id}/annotation"
    done = annotator.put(url, json=body(0, square(0, 5, 0, 5), status="done")).get_json()
    reviewer = app.test_client()
    reviewer.login_as(make_user("reviewer", "rev"))
    review_url = f"/api/label/annotations/{done['id']}/review"

    assert reviewer.post(review_url, json={"version": done["version"], "decision": "reject"}).get_json()["fields"] == {
        "comment": "required when rejecting"
    }
    assert reviewer.post(review_url, json={"version": 99, "decision": "accept"}).status_code == 409
    assert annotator.post(review_url, json={"version": done["version"], "decision": "accept"}).status_code == 403
    assert reviewer.put(url, json=body(0)).status_code == 403

    rejected = reviewer.post(review_url, json={"version": done["version"], "decision": "reject", "comment": "Include the handle."})
    assert rejected.status_code == 200 and rejected.get_json()["status"] == "rejected"
    # Back with its author: the comment is shown on the API, the page and the queue.
    mine = annotator.get(url).get_json()
    assert mine["status"] == "rejected" and mine["review_comment"] == "Include the handle." and mine["reviewer"] == "rev"
    assert b"Include the handle." in annotator.get("/label/").data
    assert reviewer.post(review_url, json={"version": mine["version"], "decision": "accept"}).status_code == 409

    fixed = annotator.put(url, json=body(mine["version"], square(0, 9, 0, 9))).get_json()
    assert fixed["status"] == "in_progress" and fixed["review_comment"] == "Include the handle."
    done = annotator.put(url, json=body(fixed["version"], square(0, 9, 0, 9), status="done")).get_json()
    assert b"Waiting for review" in reviewer.get("/label/").data
    accepted = reviewer.post(review_url, json={"version": done["version"], "decision": "accept", "comment": None}).get_json()
    assert accepted["status"] == "reviewed" and accepted["reviewer"] == "rev" and accepted["reviewed_at"]
    with reviewer.get("/label/review/next") as response:
        assert response.status_code == 302 and response.location.endswith("/label/")


def test_next_unlabelled_follows_the_dataset_order_and_skips_taken_frames(app, client, make_user):
    f1, f2, f3 = make_frames(app)
    ann, other = make_user("annotator", "ann"), make_user("annotator", "other")
    drawn = body(0, square(0, 4, 0, 4), status=None, no_action_object=False, time_spent_delta_s=0)
    nothing_there = body(0, no_action_object=True, status="done", time_spent_delta_s=0)
    with app.app_context():
        me, them = db.session.get(User, ann.id), db.session.get(User, other.id)
        first, second, third = (db.session.get(Frame, f) for f in (f1, f2, f3))
        assert labelling.next_unlabelled(me) == f1
        labelling.save_annotation(first, them, drawn)
        # f1 is someone else's now, theirs to finish.
        assert labelling.next_unlabelled(me) == f2
        assert labelling.next_unlabelled(them) == f1
        assert labelling.next_unlabelled(me, after=second) == f3
        assert labelling.next_unlabelled(me, after=third) == f2  # wraps around
        assert labelling.save_annotation(second, me, nothing_there).status is Status.DONE
        assert labelling.next_unlabelled(me, after=second) == f3
        assert labelling.next_unlabelled(me, after=third) == f3
        assert labelling.next_unlabelled(me, activity_id=first.sequence.activity_id) == f3
    client.login_as(ann)
    with client.get(f"/label/next?after={f3}") as response:
        assert response.location.endswith(f"/label/frames/{f3}")
    page = client.get("/label/")
    assert b"Next unlabelled frame" in page.data and b"kitchen" in page.data


def test_pages_render_for_their_roles(app, client, make_user):
    frame_id, *_ = make_frames(app, n=1)
    client.login_as(make_user("annotator", "ann"))
    page = client.get(f"/label/frames/{frame_id}")
    assert page.status_code == 200
    assert b'id="label-config"' in page.data and b"css/label.css" in page.data and b"Keyboard shortcuts" in page.data
    saved = client.put(f"/api/label/frames/{frame_id}/annotation", json=body(0, square(0, 5, 0, 5), status="done")).get_json()
    reviewer = app.test_client()
    reviewer.login_as(make_user("reviewer", "rev"))
    review = reviewer.get(f"/label/annotations/{saved['id']}/review")
    assert review.status_code == 200 and b'"mode": "review"' in review.data and b"Accept" in review.data
    assert reviewer.get(f"/label/frames/{frame_id}").status_code == 403
    assert client.get(f"/label/annotations/{saved['id']}/review").status_code == 403
    assert client.get("/label/frames/9999").status_code == 404
    assert client.get("/api/label/frames/9999/annotation").get_json()["fields"] == {"frame_id": "no such frame"}


def test_nobody_reviews_their_own_annotation_admins_included(app, client, make_user):
    frame_id, *_ = make_frames(app, n=1)
    admin = make_user("admin", "boss")
    client.login_as(admin)
    url = f"/api/label/frames/{frame_id}/annotation"
    done = client.put(url, json=body(0, square(0, 5, 0, 5), status="done")).get_json()
    review_url = f"/api/label/annotations/{done['id']}/review"
    for decision in ("accept", "reject"):
        response = client.post(review_url, json={"version": done["version"], "decision": decision, "comment": "fine"})
        assert response.status_code == 403 and response.get_json()["message"] == "you cannot review your own annotation"
    with client.get("/label/review/next") as response:  # the queue skips one's own
        assert response.status_code == 302 and response.location.endswith("/label/")
    page = client.get(f"/label/annotations/{done['id']}/review").get_data(as_text=True)
    assert "This is your own annotation" in page
    assert re.search(r'id="accept"[^>]*disabled', page) and re.search(r'id="reject"[^>]*disabled', page)

    other = app.test_client()
    other.login_as(make_user("admin", "other-boss"))
    assert "This is your own annotation" not in other.get(f"/label/annotations/{done['id']}/review").get_data(True)
    with other.get("/label/review/next") as response:
        assert response.location.endswith(f"/label/annotations/{done['id']}/review")
    accepted = other.post(review_url, json={"version": done["version"], "decision": "accept"})
    assert accepted.status_code == 200 and accepted.get_json()["status"] == "reviewed"
