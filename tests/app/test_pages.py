import json
import re

import cv2
import numpy as np
import pytest

from app.extensions import db
from app.models import Frame, InstanceKind
from app.models.training import Prediction
from app.services import labelling, media
from app.services.demo import create_demo
from app.services.frames import RENDERER_TRUTH_KEYS
from app.services.importing import import_path
from app.services.users import create_user
from egonet import io
from tests.app.access.training import make_prediction_fixture
from tests.app.factories import image_folder
from tests.app.test_exchange import _rle


def test_empty_index_explains_how_to_start(admin_client):
    page = admin_client.get("/")
    assert page.status_code == 200
    assert b"flask --app app egonet demo" in page.data


@pytest.mark.both_storages
def test_index_grid_viewer_and_media(app, app_with, admin_client, make_user, tmp_path):
    client = admin_client
    with app.app_context():
        import_path(image_folder(tmp_path / "rec", n=3, depth=True), activity="cooking")
    page = client.get("/")
    assert b"cooking" in page.data and b"3 frames" in page.data
    api = client.get("/api/activities").get_json()
    (activity,) = api["activities"]
    assert activity["by_status"]["todo"] == 3

    grid = client.get(f"/activities/{activity['id']}")
    assert grid.status_code == 200 and grid.data.count(b'class="frame-tile"') == 3

    frames = client.get(f"/api/activities/{activity['id']}/frames").get_json()["frames"]
    first = frames[0]
    viewer = client.get(f"/frames/{first['id']}")
    assert viewer.status_code == 200 and b"Depth" in viewer.data and b'id="next"' in viewer.data
    assert f'href="/label/frames/{first["id"]}"'.encode() in viewer.data
    other_host = app_with(STORAGE_URL=app.config["STORAGE_URL"], CACHE_ROOT=str(tmp_path / "host-2")).test_client()
    other_host.login_as(make_user("annotator", "ann"))  # another server: its own empty cache, the same storage
    for url, mimetype in ((first["rgb_url"], "image/png"), (first["depth_url"], "image/png"), (f"/frames/{first['id']}/thumb.jpg", "image/jpeg")):
        for host in (client, other_host):
            with host.get(url) as response:
                assert response.status_code == 200 and len(response.data) > 100, url
                assert response.mimetype == mimetype


def test_errors_are_json_for_the_api_and_pages_for_browsers(admin_client):
    client = admin_client
    response = client.get("/api/frames/999")
    assert response.status_code == 404
    body = response.get_json()
    assert body["error"] == "not_found" and body["message"] and body["fields"] == {}
    page = client.get("/frames/999")
    assert page.status_code == 404 and page.mimetype == "text/html" and b"Back to the activities" in page.data
    assert client.get("/activities/1?page=0").status_code in (400, 404)
    with client.get("/media/../../etc/passwd") as response:
        assert response.status_code == 404


# --------------------------------------------------------------------------
# The review queue's thumbnails, the viewer's annotations and heat-map scale, the renderer's truth


def _two_annotators(app, tmp_path, size=(48, 64)):
    """A frame with anna's done annotation (two objects) and bert's in-progress one.

    Returns:
        The frame's id, the two annotations' ids, anna's two masks.
    """
    with app.app_context():
        import_path(image_folder(tmp_path / "rec", n=2, size=size, depth=True), activity="cooking")
        frame = db.session.execute(db.select(Frame).order_by(Frame.index)).scalars().first()
        h, w = size
        left, right = np.zeros(size, bool), np.zeros(size, bool)
        left[h // 4 : h // 2, w // 8 : w // 3] = True
        right[h // 2 : 3 * h // 4, w // 2 : 7 * w // 8] = True
        body = lambda *masks, status: {  # noqa: E731
            "version": 0, "status": status, "no_action_object": False, "time_spent_delta_s": 0.0,
            "instances": [{"key": f"k{i}", "kind": k, "label": None, "mask": _rle(m)}
                          for i, (m, k) in enumerate(zip(masks, [InstanceKind.TACTILE.value, None]))],
        }
        a, _ = create_user("anna", "annotator", "anna-password-123")
        b, _ = create_user("bert", "annotator", "bert-password-123")
        done = labelling.save_annotation(frame, a, body(left, right, status="done"))
        draft = labelling.save_annotation(frame, b, body(right, status=None))
        return frame.id, done.id, draft.id, left, right


def test_a_review_tile_counts_hands_apart_from_action_objects(app, admin_client, tmp_path):
    with app.app_context():
        import_path(image_folder(tmp_path / "rec", n=1, size=(48, 64)), activity="cooking")
        frame = db.session.execute(db.select(Frame)).scalars().one()
        cup, hand = np.zeros((48, 64), bool), np.zeros((48, 64), bool)
        cup[10:20, 10:20], hand[30:40, 40:60] = True, True
        anna, _ = create_user("anna", "annotator", "anna-password-123")
        labelling.save_annotation(frame, anna, {
            "version": 0, "status": "done", "no_action_object": False, "time_spent_delta_s": 0.0,
            "instances": [{"key": "k0", "kind": InstanceKind.TACTILE.value, "label": "cup", "mask": _rle(cup)},
                          {"key": "k1", "kind": None, "label": "Hand", "mask": _rle(hand)}],
        })
    page = admin_client.get("/label/").get_data(as_text=True)
    assert "1 object: tactile · 1 hand" in page and "2 objects" not in page


def test_the_review_queue_shows_each_mask_over_its_frame(app, admin_client, tmp_path):
    frame_id, done_id, _, left, right = _two_annotators(app, tmp_path, size=(96, 128))
    page = admin_client.get("/label/").get_data(as_text=True)
    queue = page[page.index('id="review-queue"'):]
    assert f'src="/api/label/annotations/{done_id}/thumb.png?v=' in queue and "2 objects: tactile" in queue
    assert f'class="fix-link" href="/label/annotations/{done_id}/review#fix"' in queue

    with admin_client.get(f"/api/label/annotations/{done_id}/thumb.png?v=2") as response:
        assert response.status_code == 200 and response.mimetype == "image/png"
        assert "max-age=86400" in response.headers["Cache-Control"]
        data = response.data
    rgba = cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGRA2RGBA)
    assert rgba.shape == (180, 240, 4)  # the frame thumbnail's size (240 wide), whatever the frame's
    small = cv2.resize(left.astype(np.uint8), (240, 180), interpolation=cv2.INTER_NEAREST).astype(bool)
    inside = rgba[small]
    assert (inside[:, 3] > 0).all() and tuple(np.median(inside[:, :3], axis=0)) == labelling.instance_colour(0)
    other = cv2.resize(right.astype(np.uint8), (240, 180), interpolation=cv2.INTER_NEAREST).astype(bool)
    assert tuple(np.median(rgba[other][:, :3], axis=0)) == labelling.instance_colour(1)
    assert (rgba[~(small | other)][:, 3] == 0).mean() > 0.97  # transparent around them (bar the outlines' edge)
    assert (rgba[:, :, 3] == 255).sum() > 0 and (rgba[:, :, 3] == 90).sum() > 0  # outlined and faintly filled
    cache = list((tmp_path / "cache" / "derived" / "review").iterdir())
    assert len(cache) == 1
    with admin_client.get(f"/api/label/annotations/{done_id}/thumb.png") as again:
        assert again.data == data and list((tmp_path / "cache" / "derived" / "review").iterdir()) == cache


def test_the_viewer_gets_every_annotation_to_outline(app, admin_client, tmp_path):
    frame_id, done_id, draft_id, *_ = _two_annotators(app, tmp_path)
    page = admin_client.get(f"/frames/{frame_id}").get_data(as_text=True)
    config = json.loads(re.search(r'<script type="application/json" id="viewer-config">(.*?)</script>', page, re.S).group(1))
    assert [(a["id"], a["author"], a["status"], a["shown"]) for a in config["annotations"]] == [
        (done_id, "anna", "done", True), (draft_id, "bert", "in_progress", False)]
    colours = [i["colour"] for a in config["annotations"] for i in a["instances"]]
    assert colours == [list(labelling.instance_colour(k)) for k in range(3)]  # each object its own colour
    first = config["annotations"][0]["instances"]
    assert [i["kind"] for i in first] == ["tactile", None]
    with admin_client.get(first[1]["mask_url"]) as mask:
        assert mask.status_code == 200 and mask.mimetype == "image/png"
    with app.app_context():
        frame = db.session.get(Frame, frame_id)
        views = 1 + bool(frame.depth_path) + bool(frame.dhg_path)
    assert views >= 2 and page.count('canvas class="outlines layer"') == views  # over RGB, depth (and DHG)
    assert "ground truth" in page and config["prediction"] is None


def test_the_heat_map_has_a_colour_bar_and_a_display_only_stretch(app, admin_client, tmp_path):
    with app.app_context():
        import_path(image_folder(tmp_path / "rec", n=2), activity="cooking")
        frames = db.session.execute(db.select(Frame).order_by(Frame.index)).scalars().all()
        ids = make_prediction_fixture(frames[0])  # a ramp over the whole range
        prediction = db.session.get(Prediction, ids["prediction_id"])
        faint = (np.linspace(0.02, 0.08, 48 * 64).reshape(48, 64) * 65535).round().astype(np.uint16)
        prediction.frame_id = frame_id = frames[1].id
        prediction.path = media.store(io.encode_png(faint), ".png")  # a low-probability run's map
        db.session.commit()
        stored = media.read(prediction.path)

    def alpha(url):
        with admin_client.get(url) as response:
            assert response.status_code == 200 and response.mimetype == "image/png"
            return cv2.imdecode(np.frombuffer(response.data, np.uint8), cv2.IMREAD_UNCHANGED)[:, :, 3]

    page = admin_client.get(f"/frames/{frame_id}").get_data(as_text=True)
    assert 'id="normalise-prediction"' in page and "(0.02 – 0.08)" in page and "For the eye only" in page
    raw = alpha(f"/training/predictions/{ids['prediction_id']}.png")
    stretched = alpha(f"/frames/predictions/{ids['prediction_id']}/normalised.png")
    assert raw.max() <= 26 and stretched.max() == 220 and stretched.min() == 0  # invisible, then the whole scale
    with app.app_context():
        assert media.read(db.session.get(Prediction, ids["prediction_id"]).path) == stored  # the scores' map is untouched
    bar = alpha("/frames/colour-bar.png")
    assert bar.shape == (12, 256) and bar[0, 0] == 0 and bar[0, -1] == 220

    with app.app_context():  # a flat map: nothing to stretch
        prediction = db.session.get(Prediction, ids["prediction_id"])
        prediction.path = media.store(io.encode_png(np.full((48, 64), 3000, np.uint16)), ".png")
        db.session.commit()
    page = admin_client.get(f"/frames/{frame_id}").get_data(as_text=True)
    assert 'id="normalise-prediction" disabled' in page and "This map is flat" in page


def test_demo_frames_hide_the_renderers_answer(app, admin_client):
    with app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0.5, width=64, height=48)
        frame = db.session.execute(db.select(Frame).where(~Frame.annotations.any()).limit(1)).scalar_one()
        meta = dict(frame.meta)
    assert RENDERER_TRUTH_KEYS <= meta.keys()  # the renderer still writes them (a renamed key would leak)
    page = admin_client.get(f"/frames/{frame.id}").get_data(as_text=True)
    table = page[page.index('<table class="meta">'):]
    assert "<th>object</th>" not in table and "<th>kind</th>" not in table and "<th>mask_fraction</th>" not in table
    assert "<th>pitch_deg</th>" in table and "<th>seated</th>" in table  # the scene's other facts stay
    api = admin_client.get(f"/api/frames/{frame.id}").get_json()["meta"]
    assert not RENDERER_TRUTH_KEYS & api.keys() and "pitch_deg" in api
