"""Requests whose cost the client controls: each is checked before the work.

RLE strings are measured against the mask before pycocotools decodes them,
mask PNGs are refused on their author, version and header before decoding,
GrabCut calls are bounded (points, radius, the pixels the object's strokes
sweep, the frame's size), GrabCut's memory per worker is a budget of bytes,
and ids past what an id column holds (2**31 - 1) are a 404 or a 400, never
a database error (PostgreSQL refuses to compare an INTEGER with more).
"""

import re

import numpy as np
import pytest

from app.limits import MAX_ID
from app.errors import Problem
from app.extensions import db
from app.models.annotations import GrabCutState
from app.services import labelling
from app.services.labelling import grabcut as grabcut_service
from egonet.grabcut import GrabCutSession
from tests.app.access import ALL, all_url_values
from tests.app.test_access_matrix import EXPECTED
from tests.app.test_import_safety import png_claiming
from tests.app.test_labelling import H, W, body, make_frames, square
from tests.app.test_labelling_grabcut import BOX, call

HUGE_IDS = (2**31, 2**64, 10**30)


@pytest.fixture
def annotator(client, make_user):
    client.login_as(make_user("annotator", "ann"))
    return client


# --------------------------------------------------------------------------
# RLE


@pytest.mark.parametrize("length", [400_000, 2_000_000])
def test_a_huge_counts_string_is_refused_by_its_length_before_decoding(app, annotator, monkeypatch, length):
    frame_id, *_ = make_frames(app, n=1)
    request = body(0, square(0, 5, 0, 5))
    # One number of ``length`` characters: quadratic for a decoder that builds it as a Python int.
    request["instances"][0]["mask"]["counts"] = "Q" * (length - 1) + "1"

    def decoded(*args, **kwargs):
        raise AssertionError("the counts were decoded before their length was checked")

    for name in ("_unpack_counts", "_decode"):
        monkeypatch.setattr(f"egonet.rle.{name}", decoded)
    response = annotator.put(f"/api/label/frames/{frame_id}/annotation", json=request)
    assert response.status_code == 400
    limit = labelling.max_rle_chars(H * W)
    reason = response.get_json()["fields"]["instances[0].mask.counts"]
    assert reason == f"{length} characters, more than a mask of {H * W} pixels takes ({limit} at most)"
    assert annotator.get(f"/api/label/frames/{frame_id}/annotation").get_json()["version"] == 0


def test_a_number_wider_than_any_count_is_refused():
    with pytest.raises(Problem) as error:
        labelling.decode_rle({"size": [H, W], "counts": "PPPPPPP0"}, (H, W), field="m")
    assert error.value.fields == {"m.counts": "a number of 8 characters; no count of this mask takes more than 4"}


# --------------------------------------------------------------------------
# Mask PNG uploads


def test_a_mask_png_is_checked_for_author_version_and_size_before_it_is_decoded(app, annotator, make_user):
    frame_id, *_ = make_frames(app, n=1)
    saved = annotator.put(f"/api/label/frames/{frame_id}/annotation", json=body(0, square(0, 5, 0, 5))).get_json()
    url = f"/api/label/annotations/{saved['id']}/instances/0/mask.png"
    bomb, wrong_size = png_claiming(100_000, 100_000), png_claiming(W + 1, H)

    other = app.test_client()
    other.login_as(make_user("annotator", "someone-else"))
    for png in (bomb, wrong_size):
        response = other.put(f"{url}?version={saved['version']}", data=png, content_type="image/png")
        assert response.status_code == 403, response.get_json()
    response = annotator.put(f"{url}?version={saved['version'] + 1}", data=bomb, content_type="image/png")
    assert response.status_code == 409

    # These PNGs hold no pixels: decoding them would say "not a readable PNG".
    response = annotator.put(f"{url}?version={saved['version']}", data=wrong_size, content_type="image/png")
    assert response.status_code == 400
    assert response.get_json()["fields"] == {"mask": f"must be {W}x{H} like the frame, got {W + 1}x{H}"}
    response = annotator.put(f"{url}?version={saved['version']}", data=png_claiming(W, H), content_type="image/png")
    assert response.status_code == 400 and "not a readable PNG" in response.get_json()["message"]


# --------------------------------------------------------------------------
# GrabCut: what one call may cost


def stroke(client, frame_id, points, radius, instance="a"):
    return call(client, "stroke", frame_id=frame_id, instance=instance, points=points, label="bg", radius=radius)


def test_strokes_past_the_point_and_radius_limits_are_400_naming_the_field(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    app.config.update(GRABCUT_MAX_STROKE_POINTS=50, GRABCUT_MAX_RADIUS=10)
    call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    line = [[40 + i, 60] for i in range(50)]
    assert stroke(annotator, frame_id, line, 10)[0] == "1"
    status, error = stroke(annotator, frame_id, line + [[95, 60]], 10)
    assert status == 400 and error["fields"] == {"points": "must have 0-50 items"}
    status, error = stroke(annotator, frame_id, line, 10.5)
    assert status == 400 and error["fields"] == {"radius": "must be > 0 and <= 10"}


def test_stroke_pixels_by_hand():
    # One point: its disk's box, 5x5, once for the segment and once for the stroke's crop.
    assert labelling.stroke_pixels((100, 100), [[10, 10]], 2) == 2 * 25
    # A segment along the top edge, radius 1: columns 0-10, rows 0-1 (clipped), twice.
    assert labelling.stroke_pixels((100, 100), [[0, 0], [9, 0]], 1) == 2 * 11 * 2
    # An L: the segments' boxes are thin, the crop is the whole square.
    assert labelling.stroke_pixels((100, 100), [[0, 0], [99, 0], [99, 99]], 0.5) == 100 * 2 + 2 * 100 + 100 * 100


def test_the_pixels_an_objects_strokes_sweep_are_bounded(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    first, second = [[50, 40], [110, 40]], [[50, 80], [110, 80]]
    sweep = labelling.stroke_pixels((H, W), first, 3)
    assert labelling.stroke_pixels((H, W), second, 3) == sweep
    app.config["GRABCUT_MAX_STROKE_PIXELS"] = sweep * 3 // 2
    call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)

    status, error = stroke(annotator, frame_id, [[0, 0], [W - 1, H - 1]], 3)
    assert status == 400 and "the stroke sweeps" in error["fields"]["points"]
    assert stroke(annotator, frame_id, first, 3)[0] == "1"
    status, error = stroke(annotator, frame_id, second, 3)
    assert status == 400 and "the object's strokes would sweep" in error["message"] and "points" in error["fields"]
    # Undoing the first stroke makes room for the second; a new box starts afresh.
    call(annotator, "undo", frame_id=frame_id, instance="a")
    assert stroke(annotator, frame_id, second, 3)[0] == "1"
    call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    assert stroke(annotator, frame_id, first, 3)[0] == "1"


def test_grabcut_on_a_frame_over_the_side_limit_is_refused_naming_it(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    app.config["MAX_FRAME_SIDE"] = W - 1  # the frame was imported under a larger limit
    dot = {"points": [[60, 60]], "label": "bg", "radius": 3}
    for op, extra in (("box", {"box": BOX}), ("stroke", dot), ("undo", {})):
        status, error = call(annotator, op, frame_id=frame_id, instance="a", **extra)
        assert status == 400, (op, error)
        assert error["fields"] == {"frame_id": f"larger than {W - 1} pixels a side"}
        assert error["message"].startswith(f"frame_id: frame {frame_id} is {W}x{H}, larger than")
    with annotator.get(f"/api/label/grabcut/mask.png?frame_id={frame_id}&instance=a") as response:
        assert response.status_code == 400 and "frame_id" in response.get_json()["fields"]


# --------------------------------------------------------------------------
# GrabCut: memory kept per worker


def test_the_recent_cache_keeps_within_its_byte_budget_least_recent_out_first():
    cache = grabcut_service._Recent()
    for key in "abc":
        cache.put(key, key.upper(), nbytes=10, budget=25)
    assert cache.keys() == ["b", "c"] and cache.nbytes == 20
    assert cache.get("b") == "B"  # now the most recent
    cache.put("d", "D", nbytes=10, budget=25)
    assert cache.keys() == ["b", "d"] and cache.nbytes == 20
    cache.put("e", "E", nbytes=30, budget=25)  # larger than the budget: not kept, nothing evicted
    assert cache.keys() == ["b", "d"] and cache.get("e") is None
    cache.put("b", "B2", nbytes=20, budget=25)  # a new size for a kept key
    assert cache.keys() == ["b"] and cache.nbytes == 20
    assert cache.take("b") == "B2" and cache.nbytes == 0 and cache.keys() == []


def test_a_session_is_sized_by_its_arrays():
    image = np.random.default_rng(0).integers(0, 255, (H, W, 3), dtype=np.uint8)
    session = GrabCutSession(image)
    assert session.nbytes == image.nbytes + H * W  # its own copy of the frame, and the mask
    session.box(*BOX)
    boxed = session.nbytes
    assert boxed > image.nbytes + H * W
    session.stroke([[0, 0], [W - 1, H - 1]], "fg", 2)
    assert session.nbytes >= boxed + H * W  # the stroke's footprint covers the frame


def test_grabcut_sessions_are_kept_within_the_byte_budget(app, annotator, monkeypatch):
    monkeypatch.setattr(grabcut_service, "_sessions", grabcut_service._Recent())
    frame_id, *_ = make_frames(app, n=1)
    call(annotator, "box", frame_id=frame_id, instance="o0", box=BOX)
    one = grabcut_service._sessions.nbytes
    assert one > H * W  # its own arrays (the mask, the undo levels): the frame and its guides are kept apart
    budget = one * 5 // 2
    app.config["GRABCUT_CACHE_BYTES"] = budget
    for key in ("o1", "o2", "o3"):
        call(annotator, "box", frame_id=frame_id, instance=key, box=BOX)
        assert grabcut_service._sessions.nbytes <= budget
    with app.app_context():
        revisions = dict(db.session.execute(db.select(GrabCutState.instance_key, GrabCutState.revision)).all())
    assert grabcut_service._sessions.keys() == [revisions["o2"], revisions["o3"]]  # the least recent went first
    # A session that was let go is restored from its row.
    assert stroke(annotator, frame_id, [[60, 60]], 3, instance="o0")[0] == "1"

    app.config["GRABCUT_CACHE_BYTES"] = one // 2  # smaller than one session: none is kept, all still work
    app.config["GRABCUT_IMAGE_CACHE_BYTES"] = H * W * 3 - 1
    monkeypatch.setattr(grabcut_service, "_sessions", grabcut_service._Recent())
    monkeypatch.setattr(grabcut_service, "_frames", grabcut_service._Recent())
    assert stroke(annotator, frame_id, [[60, 60]], 3, instance="o1")[0] == "1"
    assert grabcut_service._sessions.keys() == [] and grabcut_service._frames.keys() == []


# --------------------------------------------------------------------------
# Ids past what an id column holds


def int_routes(app):
    for rule in app.url_map.iter_rules():
        names = re.findall(r"<int:(\w+)>", rule.rule)
        if names:
            yield rule, names


def test_path_ids_past_the_id_columns_are_404_for_every_role_that_may_use_the_route(app, client, make_user, tmp_path):
    values = all_url_values(app, tmp_path)
    routes = list(int_routes(app))
    assert len(routes) > 10
    for role in sorted(ALL):
        client.login_as(make_user(role, f"huge-{role.value}"))
        for rule, names in routes:
            allowed, _ = EXPECTED[rule.endpoint]
            if allowed is not None and role not in allowed:
                continue
            for name in names:
                for value in (*HUGE_IDS, MAX_ID):  # the largest id that fits is a plain "no such thing"
                    url = rule.build({**values, name: value}, append_unknown=False)[1]
                    for method in sorted(rule.methods - {"HEAD", "OPTIONS"}):
                        with client.open(url, method=method) as response:
                            got = response.status_code
                        assert got == 404 if value > MAX_ID else got < 500, f"{role} {method} {url}: {got}"


@pytest.mark.parametrize("huge", HUGE_IDS)
def test_ids_past_the_id_columns_in_bodies_and_queries_are_400_naming_them(app, annotator, make_user, huge):
    frame_id, *_ = make_frames(app, n=1)
    saved = annotator.put(f"/api/label/frames/{frame_id}/annotation", json=body(0, square(0, 5, 0, 5))).get_json()
    for op, extra in (("box", {"box": BOX}), ("undo", {})):
        status, error = call(annotator, op, frame_id=huge, instance="a", **extra)
        assert status == 400 and error["fields"] == {"frame_id": "must be <= 2147483647"}
    status, error = stroke(annotator, frame_id, [[60, 60]], 10**400)
    assert status == 400 and error["fields"] == {"radius": "must be a finite number"}
    queries = [
        (annotator, f"/api/label/grabcut/mask.png?frame_id={huge}&instance=a", "frame_id"),
        (annotator, f"/label/next?after={huge}", "after"),
        (annotator, f"/label/next?activity={huge}", "activity"),
    ]
    reviewer = app.test_client()
    reviewer.login_as(make_user("reviewer", "rev"))
    queries.append((reviewer, f"/label/review/next?after={huge}", "after"))
    for client, url, name in queries:
        with client.get(url, headers={"Accept": "application/json"}) as response:
            assert response.status_code == 400, (url, response.status_code)
            assert name in response.get_json()["fields"]
    url = f"/api/label/annotations/{saved['id']}/instances/0/mask.png?version={huge}"
    response = annotator.put(url, data=b"", content_type="image/png")
    assert response.status_code == 400 and response.get_json()["fields"] == {"version": "must be <= 2147483647"}
