"""GrabCut with the frame's depth through the app: the box request's
``use_depth``, sessions restored with their depth, the page's toggle, and
the real RGB-D chair frame imported as a user would."""

import io as stdio
import zlib
from pathlib import Path

import numpy as np
import pytest

from app.extensions import db
from app.models import Activity, Frame, Sequence
from app.models.annotations import GrabCutState
from app.services import media
from app.services.importing import FrameItem, add_frames, import_path
from app.services.labelling import grabcut as grabcut_service
from egonet import io
from egonet.grabcut import GrabCutSession
from tests.app.test_labelling_grabcut import call, forget_everything, iou
from tests.realdata import PRIMESENSE, chair_truth


H, W = 120, 160
PANEL = (slice(40, 90), slice(50, 120))
BOX = [40, 30, 130, 100]


@pytest.fixture
def annotator(client, make_user):
    client.login_as(make_user("annotator", "ann"))
    return client


def white_on_white() -> tuple[np.ndarray, np.ndarray]:
    """A white panel 0.4 m before a white wall (``PANEL``): only depth tells them apart."""
    rng = np.random.default_rng(0)
    image = np.clip(rng.normal(225, 6, (H, W, 3)), 0, 255).astype(np.uint8)
    depth = np.full((H, W), 2.0) + rng.normal(0, 0.004, (H, W))
    depth[PANEL] -= 0.4
    return image, depth.astype(np.float32)


def truth() -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[PANEL] = True
    return mask


def make_frame(app, *, with_depth: bool, activity: str = "wall") -> int:
    image, depth = white_on_white()
    item = FrameItem("f000", 0, "panel", rgb=image, depth_m=depth if with_depth else None)
    with app.app_context():
        add_frames(activity=activity, sequence="s1", items=[item])
        query = db.select(Frame.id).join(Sequence).join(Activity).where(Activity.name == activity)
        return db.session.execute(query).scalar_one()


def saved_state(app, frame_id: int, key: str) -> dict:
    with app.app_context():
        row = db.session.execute(db.select(GrabCutState).filter_by(frame_id=frame_id, instance_key=key)).scalar_one()
        with np.load(stdio.BytesIO(zlib.decompress(row.state))) as arrays:
            return dict(arrays)


def stored_depth_path(app, frame_id: int) -> Path:
    with app.app_context():
        return media.local_path(db.session.get(Frame, frame_id).depth_path)


def test_a_box_uses_the_frames_depth_unless_told_not_to(app, annotator):
    frame_id = make_frame(app, with_depth=True)
    _, with_depth = call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    assert iou(with_depth, truth()) > 0.95
    assert saved_state(app, frame_id, "a")["uses_depth"] == 1
    _, told = call(annotator, "box", frame_id=frame_id, instance="b", box=BOX, use_depth=True)
    assert np.array_equal(told, with_depth)
    # Colour only: exactly the engine's colour-only answer, which misses the panel.
    _, without = call(annotator, "box", frame_id=frame_id, instance="c", box=BOX, use_depth=False)
    image, _ = white_on_white()
    assert np.array_equal(without, GrabCutSession(image).box(*BOX))
    assert iou(without, truth()) < 0.8
    assert "uses_depth" not in saved_state(app, frame_id, "c")


def test_a_session_keeps_its_choice_and_a_new_box_takes_a_new_one(app, annotator, monkeypatch):
    frame_id = make_frame(app, with_depth=True)
    image, _ = white_on_white()
    stroke = {"points": [[60, 60], [75, 60]], "label": "bg", "radius": 3}
    engine = GrabCutSession(image, io.read_depth(stored_depth_path(app, frame_id)))
    engine.box(*BOX)
    expected = engine.stroke(stroke["points"], stroke["label"], stroke["radius"])
    call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    # The stroke is served by a worker that has nothing in memory: the session
    # comes from the database and is given the frame's depth again.
    forget_everything(app, monkeypatch)
    _, stroked = call(annotator, "stroke", frame_id=frame_id, instance="a", **stroke)
    assert np.array_equal(stroked, expected)
    assert iou(stroked, truth()) > 0.9
    # Turning depth off applies from the next box: the object starts again in colour only.
    _, boxed = call(annotator, "box", frame_id=frame_id, instance="a", box=BOX, use_depth=False)
    assert np.array_equal(boxed, GrabCutSession(image).box(*BOX))
    assert "uses_depth" not in saved_state(app, frame_id, "a")
    _, undone = call(annotator, "undo", frame_id=frame_id, instance="a")
    assert not undone.any()  # a session cannot change its kind, so nothing before that box


def test_the_frame_is_kept_with_its_depth_and_its_guides(app, annotator, monkeypatch):
    """A worker keeps the frame for GrabCut (image, depth, its ROIs' guides): a session restored
    from the database builds no guide again, and nothing is kept without room for it."""
    from egonet.grabcut import frame as grabcut_frame

    monkeypatch.setattr(grabcut_service, "_frames", grabcut_service._Recent())
    frame_id = make_frame(app, with_depth=True)
    call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    with app.app_context():
        frame = db.session.get(Frame, frame_id)
        key = (frame.rgb_path, frame.depth_path)
    assert grabcut_service._frames.keys() == [key]
    kept = grabcut_service._frames.get(key)
    assert kept.depth.dtype == np.float32 and kept.depth.shape == (H, W) and kept.guides == 2  # colour and depth
    assert grabcut_service._frames.nbytes == kept.nbytes > H * W * 3 + H * W * 4
    built = []
    for cls in (grabcut_frame._Guide, grabcut_frame._DepthGuide):
        monkeypatch.setattr(cls, "build", lambda *a, _b=cls.build, **k: built.append(1) or _b(*a, **k))
    monkeypatch.setattr(grabcut_service, "_sessions", grabcut_service._Recent())  # restored from its row
    status, mask = call(annotator, "stroke", frame_id=frame_id, instance="a", points=[[60, 60]], label="bg", radius=3)
    assert status == "1" and not mask[60, 60] and built == []
    # Another worker (nothing in memory) loads the guides the first one shared on disk: it builds none
    # either, and cuts exactly as the engine does.
    shared = {p.name.split("-")[2] for p in (Path(app.config["CACHE_ROOT"]) / "grabcut-frames").glob("*-v*.npy")}
    assert shared == {"colour", "depth"}
    monkeypatch.setattr(grabcut_service, "_frames", grabcut_service._Recent())
    monkeypatch.setattr(grabcut_service, "_sessions", grabcut_service._Recent())
    _, mask = call(annotator, "stroke", frame_id=frame_id, instance="a", points=[[70, 64]], label="bg", radius=3)
    assert built == []
    mapped = grabcut_service._frames.get(key)  # the shared copies, not this worker's own
    assert isinstance(mapped.image, np.memmap) and isinstance(mapped.depth, np.memmap)
    engine = GrabCutSession(np.array(kept.image), np.array(kept.depth))  # the stored frame, its own guides
    engine.box(*BOX)
    engine.stroke([(60, 60)], "bg", 3)
    assert np.array_equal(mask, engine.stroke([(70, 64)], "bg", 3))
    # Without room for it, nothing is kept and the box still works.
    monkeypatch.setattr(grabcut_service, "_frames", grabcut_service._Recent())
    monkeypatch.setitem(app.config, "GRABCUT_IMAGE_CACHE_BYTES", H * W * 3)
    _, mask = call(annotator, "box", frame_id=frame_id, instance="b", box=BOX)
    assert iou(mask, truth()) > 0.95 and grabcut_service._frames.keys() == []


@pytest.mark.parametrize(
    "value, with_depth, message",
    [(True, False, "has no depth"), ("yes", True, "must be true or false"), (1, True, "must be true or false")],
)
def test_bad_use_depth_is_a_400_naming_it(app, annotator, value, with_depth, message):
    frame_id = make_frame(app, with_depth=with_depth)
    status, error = call(annotator, "box", frame_id=frame_id, instance="a", box=BOX, use_depth=value)
    assert status == 400 and message in error["fields"]["use_depth"]


def test_a_frame_without_depth_is_cut_in_colour(app, annotator):
    frame_id = make_frame(app, with_depth=False)
    image, _ = white_on_white()
    for extra in ({}, {"use_depth": None}, {"use_depth": False}):
        _, mask = call(annotator, "box", frame_id=frame_id, instance="a", box=BOX, **extra)
        assert np.array_equal(mask, GrabCutSession(image).box(*BOX))


def test_the_page_has_the_toggle_on_with_depth_and_disabled_without(app, annotator):
    with_depth = make_frame(app, with_depth=True, activity="a1")
    without = make_frame(app, with_depth=False, activity="a2")
    page = annotator.get(f"/label/frames/{with_depth}").get_data(as_text=True)
    toggle = page[page.index('id="use-depth"') - 40:page.index('id="use-depth"') + 60]
    assert "checked" in toggle and "disabled" not in toggle
    assert "Applies from the next box" in page
    page = annotator.get(f"/label/frames/{without}").get_data(as_text=True)
    toggle = page[page.index('id="use-depth"'):page.index('id="use-depth"') + 60]
    assert "disabled" in toggle and "checked" not in toggle
    assert 'title="This frame has no depth' in page


@pytest.mark.skipif(not PRIMESENSE.exists(), reason="shared data not present")
def test_real_chair_backrest_comes_in_with_the_imported_depth(app, annotator, monkeypatch):
    with app.app_context():
        import_path(PRIMESENSE, activity="room")
        frame = db.session.execute(db.select(Frame).filter_by(index=1)).scalar_one()
        frame_id, image = frame.id, io.read_image(media.local_path(frame.rgb_path))
    box = [335, 105, 610, 390]
    # Background strokes on the wall (as the engine's test): under the seat,
    # through the right armrest's loop, left of the left leg.
    strokes = [([[420, 322], [540, 322]], 8), ([[505, 222], [560, 222]], 6), ([[355, 305], [362, 335]], 5)]
    forget_everything(app, monkeypatch)  # each request restores the session from the database
    results = {}
    for key, extra in (("depth", {}), ("rgb", {"use_depth": False})):
        _, first = call(annotator, "box", frame_id=frame_id, instance=key, box=box, **extra)
        for points, radius in strokes:
            _, final = call(annotator, "stroke", frame_id=frame_id, instance=key, points=points, label="bg", radius=radius)
        results[key] = first, final
    depth_box, depth_final = results["depth"]
    rgb_box, rgb_final = results["rgb"]
    # Colour alone cannot tell the white backrest from the white wall (it
    # leaves it out or takes the wall in too); the frame's depth brings it in
    # from the box alone.
    truth = chair_truth()
    assert iou(rgb_final, truth) < 0.65 < 0.8 < iou(depth_final, truth)
    for x, y in ((420, 150), (370, 130), (470, 180), (450, 270)):
        assert depth_box[y, x] and depth_final[y, x], (x, y)
    # The wall between the right armrest and the backrest, and under the seat, stays out.
    for x, y in ((520, 208), (575, 232), (470, 320), (520, 335), (350, 290)):
        assert not depth_final[y, x], (x, y)
    # use_depth false is the plain colour-only session on the same image.
    assert np.array_equal(rgb_box, GrabCutSession(image).box(*box))
