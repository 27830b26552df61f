"""Tests for GrabCut with depth: ``GrabCutSession(image, depth)``."""

import io

import cv2
import numpy as np
import pytest

from egonet.errors import EgonetError
from egonet.grabcut import GrabCutSession
from egonet.grabcut.graph import _JUMP, _links
from tests.realdata import PRIMESENSE, chair_truth



def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return np.count_nonzero(a & b) / max(np.count_nonzero(a | b), 1)


def _white_on_white(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A white panel 0.4 m in front of a white wall: colour alone cannot tell them apart.

    Returns ``(image, depth, truth)``: the image is one noisy white, the
    depth 2.0 m on the wall and 1.6 m on the panel (rows 40-90, columns
    50-120 of a 160x120 frame), with sensor-like noise.
    """
    rng = np.random.default_rng(seed)
    h, w = 120, 160
    truth = np.zeros((h, w), bool)
    truth[40:90, 50:120] = True
    image = np.clip(rng.normal(225, 6, (h, w, 3)), 0, 255).astype(np.uint8)
    depth = np.where(truth, 1.6, 2.0) + rng.normal(0, 0.004, (h, w))
    return image, depth, truth


def _two_colours(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A red disk on green (colour separates them), 160x120."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:120, 0:160]
    truth = (xx - 80) ** 2 + (yy - 60) ** 2 <= 30**2
    image = np.where(truth[..., None], (190, 60, 50), (60, 150, 70)) + rng.normal(0, 10, (120, 160, 3))
    return np.clip(image, 0, 255).astype(np.uint8), truth


# ------------------------------------------------------------ the depth term


def test_depth_separates_what_colour_cannot():
    image, depth, truth = _white_on_white()
    with_depth = GrabCutSession(image, depth).box(40, 30, 130, 100)
    assert _iou(with_depth, truth) > 0.95
    # The same box without depth cannot find the panel: it is the wall's colour.
    without = GrabCutSession(image).box(40, 30, 130, 100)
    assert _iou(without, truth) < 0.8


def test_links_fall_at_depth_jumps_only():
    # 1x3 grid, one colour: pixel 1 -> 2 is a 0.5 m jump, 0 -> 1 is flat.
    colour = np.full((1, 3, 3), 200.0)
    p, q, weight = _links(colour, np.array([[2.0, 2.0, 1.5]]))
    by_pair = {(int(a), int(b)): float(c) for a, b, c in zip(p, q, weight)}
    assert by_pair[(0, 1)] == pytest.approx(50.0)  # gamma: no colour change, no depth change
    assert by_pair[(1, 2)] < 1e-6 * by_pair[(0, 1)]
    # A 1 % step (sensor quantisation) keeps most of the weight: exp(-(0.01 / _JUMP)^2).
    _, _, weight = _links(colour, np.array([[2.0, 2.02, 2.02]]))
    assert weight[0] == pytest.approx(50.0 * np.exp(-((0.02 / (_JUMP * 2.0)) ** 2)))
    # Where a pixel has no depth the link is colour only.
    _, _, weight = _links(colour, np.array([[2.0, np.nan, 1.0]]))
    np.testing.assert_allclose(weight, 50.0)


def test_missing_depth_falls_back_to_colour():
    image, truth = _two_colours()
    box = (40, 20, 121, 101)
    plain = GrabCutSession(image).box(*box)
    # No depth anywhere (0 and NaN both mean missing): colour alone still finds the disk.
    for empty in (np.zeros(truth.shape), np.full(truth.shape, np.nan)):
        mask = GrabCutSession(image, empty).box(*box)
        assert _iou(mask, truth) > 0.9
        assert _iou(mask, plain) > 0.9


def test_partly_missing_depth_still_uses_the_rest():
    image, depth, truth = _white_on_white(seed=1)
    depth[:, :60] = 0  # the panel's left part and the wall beside it have no depth
    mask = GrabCutSession(image, depth).box(40, 30, 130, 100)
    known = np.zeros_like(truth)
    known[:, 60:] = True
    assert _iou(mask & known, truth & known) > 0.95


def test_strokes_are_hard_constraints_with_depth():
    image, depth, truth = _white_on_white()
    s = GrabCutSession(image, depth)
    before = s.box(40, 30, 130, 100)
    after = s.stroke([(80, 60), (100, 60)], "bg", 4)
    assert not after[56:65, 80:101].any()
    assert not (after & ~before).any()  # a background stroke only removes pixels
    grown = s.stroke([(45, 35)], "fg", 3)
    assert grown[35, 45] and not (after & ~grown).any()  # a foreground stroke only adds
    np.testing.assert_array_equal(s.undo(), after)


def test_no_depth_is_the_colour_session():
    image, truth = _two_colours()
    a = GrabCutSession(image)
    b = GrabCutSession(image, None)
    np.testing.assert_array_equal(a.box(40, 20, 121, 101), b.box(40, 20, 121, 101))
    assert not a.uses_depth
    assert "uses_depth" not in a.state()
    assert a.state()["models"].shape[-1] == 65


# ------------------------------------------------------------------ state


def test_state_round_trip_with_depth():
    image, depth, truth = _white_on_white()
    s = GrabCutSession(image, depth)
    s.box(40, 30, 130, 100)
    s.stroke([(60, 50)], "bg", 3)
    state = s.state()
    assert int(state["uses_depth"]) == 1 and state["models"].shape == (3, 2, 105)
    buf = io.BytesIO()
    np.savez(buf, **state)
    buf.seek(0)
    t = GrabCutSession.from_state(image, dict(np.load(buf)), depth)
    assert t.uses_depth
    np.testing.assert_array_equal(t.mask, s.mask)
    np.testing.assert_array_equal(t.stroke([(110, 80)], "bg", 3), s.stroke([(110, 80)], "bg", 3))
    np.testing.assert_array_equal(t.undo(), s.undo())


def test_state_and_depth_must_agree():
    image, depth, _ = _white_on_white()
    s = GrabCutSession(image, depth)
    s.box(40, 30, 130, 100)
    with pytest.raises(EgonetError, match="made with depth") as err:
        GrabCutSession.from_state(image, s.state())
    assert err.value.field == "depth"
    with pytest.raises(EgonetError, match="H, W") as err:
        GrabCutSession.from_state(image, s.state(), depth[:, :-1])
    assert err.value.field == "depth"
    plain = GrabCutSession(image)
    plain.box(40, 30, 130, 100)
    with pytest.raises(EgonetError, match="without depth") as err:
        GrabCutSession.from_state(image, plain.state(), depth)
    assert err.value.field == "depth"


@pytest.mark.parametrize(("depth", "match"), [
    (np.ones((120, 159)), "H, W"),
    (np.ones((120, 160, 1)), "H, W"),
    ([[1.0] * 160] * 120, "numpy array"),
    (np.full((120, 160), -1.0), ">= 0"),
    (np.full((120, 160), np.inf), ">= 0"),
    (np.full((120, 160), 1500.0), "millimetres"),
    (np.ones((120, 160), bool), "H, W"),
    (np.full((120, 160), 2000, np.uint16), "millimetres"),
])
def test_bad_depth(depth, match):
    image, _, _ = _white_on_white()
    with pytest.raises(EgonetError, match=match) as err:
        GrabCutSession(image, depth)
    assert err.value.field == "depth"


def test_depth_is_copied():
    image, depth, truth = _white_on_white()
    s = GrabCutSession(image, depth)
    depth[...] = 2.0  # the caller's array changes after the session was made
    assert _iou(s.box(40, 30, 130, 100), truth) > 0.95


# ------------------------------------------------------ the real RGB-D frame


@pytest.mark.skipif(not PRIMESENSE.exists(), reason="shared data not present")
def test_real_chair_backrest_comes_in_with_depth():
    bgr = cv2.imread(str(PRIMESENSE / "color" / "00001.jpg"), cv2.IMREAD_COLOR)
    image = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    depth = cv2.imread(str(PRIMESENSE / "depth" / "00001.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000
    truth = chair_truth()
    box = (335, 105, 610, 390)
    # Background strokes on the wall: under the seat, through the right armrest's loop, left of the left leg.
    strokes = [([(420, 322), (540, 322)], "bg", 8), ([(505, 222), (560, 222)], "bg", 6),
               ([(355, 305), (362, 335)], "bg", 5)]
    masks = {}
    for name, d in (("rgb", None), ("depth", depth)):
        s = GrabCutSession(image, d)
        first = s.box(*box)
        for points, label, radius in strokes:
            s.stroke(points, label, radius)
        masks[name] = (first, s.mask)
    rgb_box, rgb = masks["rgb"]
    depth_box, final = masks["depth"]
    # Colour alone cannot tell the white backrest from the white wall: it
    # leaves the backrest out or takes the wall in with it, strokes or not ...
    assert _iou(rgb_box, truth) < 0.6 and _iou(rgb, truth) < 0.65
    # ... with depth it comes in from the box alone, and stays in.
    for x, y in ((420, 150), (370, 130), (470, 180), (450, 270)):
        assert depth_box[y, x] and final[y, x], (x, y)
    # The wall between the right armrest and the backrest, and under the seat, is out.
    for x, y in ((520, 208), (575, 232), (470, 320), (520, 335), (350, 290)):
        assert not final[y, x], (x, y)
    assert _iou(final, truth) > 0.8
    assert _iou(final, truth) > _iou(rgb, truth) + 0.25


@pytest.mark.parametrize("seed", range(4))
def test_random_frames_with_holes_in_depth(seed):
    # Odd sizes, noise, depth missing in blobs and at random pixels, tiny and
    # frame-wide boxes: the session keeps its promises (mask shape, box
    # clipping, strokes as hard constraints, exact resume).
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(20, 90)), int(rng.integers(20, 90))
    image = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    depth = rng.uniform(0.5, 4.0, (h, w))
    depth[rng.random((h, w)) < 0.3] = 0
    depth[: h // 3, : w // 3] = np.nan
    x0, y0 = int(rng.integers(0, w // 2)), int(rng.integers(0, h // 2))
    x1, y1 = int(rng.integers(x0 + 1, w)), int(rng.integers(y0 + 1, h))
    s = GrabCutSession(image, depth)
    mask = s.box(x0, y0, x1, y1)
    assert mask.shape == (h, w) and not mask[:y0].any() and not mask[:, x1:].any()
    point = (float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1)))
    mask = s.stroke([point], "fg", 2)
    assert mask[int(round(point[1])), int(round(point[0]))]
    state = s.state()
    t = GrabCutSession.from_state(image, state, depth)
    np.testing.assert_array_equal(t.stroke([(x0, y0)], "bg", 1.5), s.stroke([(x0, y0)], "bg", 1.5))
    assert not s.mask[y0, x0]


# ------------------------------------------------ frames sharing their guides


class _NpzStore:
    """A ``GuideStore`` that keeps each guide as the bytes of an ``.npz``, as the app's files do."""

    def __init__(self):
        self.files: dict[str, bytes] = {}

    def load(self, name):
        if name not in self.files:
            return None
        with np.load(io.BytesIO(self.files[name]), allow_pickle=False) as arrays:
            return dict(arrays)

    def save(self, name, arrays):
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        self.files[name] = buffer.getvalue()


@pytest.mark.parametrize("with_depth", [True, False])
def test_a_frame_in_another_process_loads_the_guides_instead_of_building_them(monkeypatch, with_depth):
    from egonet.grabcut import GrabCutFrame
    from egonet.grabcut import frame as grabcut_frame

    if with_depth:
        image, depth, _ = _white_on_white()
    else:
        (image, _), depth = _two_colours(), None
    store = _NpzStore()
    first = GrabCutFrame(image, depth, store=store)
    session = GrabCutSession(first)
    session.box(40, 30, 130, 100)
    state = session.state()
    assert first.share() == (2 if with_depth else 1) and first.share() == 0  # saved once
    names = sorted(store.files)
    kinds = [name.split("-")[1] for name in names]
    assert kinds == (["colour", "depth"] if with_depth else ["colour"])
    # The colour cut's links go with the colour guide only where the colour cut made them.
    colour = store.load(names[0])
    assert ("links_p" in colour) == (not with_depth)

    def no_build(*args, **kwargs):
        raise AssertionError("built again")

    for cls in (grabcut_frame._Guide, grabcut_frame._DepthGuide):
        monkeypatch.setattr(cls, "build", no_build)
    monkeypatch.setattr("egonet.grabcut.refine._links", no_build)  # a colour guide's links
    other = GrabCutFrame(image, depth, store=store)  # another process: nothing in memory
    restored = GrabCutSession.from_state(other, state)
    assert np.array_equal(restored.stroke([(85, 65)], "bg", 4), session.stroke([(85, 65)], "bg", 4))
    assert other.share() == 0  # it had them from the store


def test_a_damaged_or_foreign_stored_guide_is_built_again_and_replaced():
    from egonet.grabcut import GrabCutFrame

    image, depth, _ = _white_on_white()
    store = _NpzStore()
    first = GrabCutFrame(image, depth, store=store)
    expected = GrabCutSession(first).box(40, 30, 130, 100)
    first.share()
    for name in list(store.files):  # every guide the wrong size for its ROI
        arrays = store.load(name)
        store.save(name, {key: value[:-1] for key, value in arrays.items()})
    damaged = dict(store.files)
    other = GrabCutFrame(image, depth, store=store)
    assert np.array_equal(GrabCutSession(other).box(40, 30, 130, 100), expected)
    assert other.share() == 2 and all(store.files[name] != damaged[name] for name in damaged)


def test_a_read_only_frame_is_shared_as_it_is_and_anything_else_copied():
    from egonet.grabcut import GrabCutFrame

    image, depth, _ = _white_on_white()
    writeable = GrabCutFrame(image, depth)
    assert not np.shares_memory(writeable.image, image) and writeable.depth.dtype == np.float32
    image.flags.writeable = False
    z = depth.astype(np.float32)
    z.flags.writeable = False
    frame = GrabCutFrame(image, z)  # e.g. memory-mapped copies, shared by processes
    assert frame.image is image and frame.depth is z
    with_zeros = z.copy()
    with_zeros[0, 0] = 0  # missing: becomes NaN in GrabCut's own copy, the caller's array untouched
    with_zeros.flags.writeable = False
    other = GrabCutFrame(image, with_zeros)
    assert other.depth is not with_zeros and np.isnan(other.depth[0, 0]) and with_zeros[0, 0] == 0
