"""Tests for egonet.grabcut: the interactive GrabCut session."""

import doctest
import importlib
import io
import math
import pkgutil
import subprocess
import sys

import cv2
import numpy as np
import pytest

import egonet.grabcut as grabcut
from egonet import synth
from egonet.grabcut import GrabCutSession, stroke_footprint
from egonet.grabcut.cut import _NEAR_GRID, _STROKE_REACH, _keep_connected
from egonet.grabcut.strokes import _polyline_distance_mask


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return np.count_nonzero(a & b) / max(np.count_nonzero(a | b), 1)


def _scene(width: int = 200, height: int = 150, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Greenish noisy background, a reddish ellipse-plus-bar object."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width]
    cx, cy = width * 0.5, height * 0.5
    truth = ((xx - cx) / (width * 0.22)) ** 2 + ((yy - cy) / (height * 0.25)) ** 2 <= 1
    truth |= (np.abs(yy - cy) < height * 0.05) & (xx > cx) & (xx < cx + width * 0.32)
    image = np.empty((height, width, 3), np.float64)
    image[...] = (60, 140, 70)
    image[truth] = (190, 70, 60)
    image += rng.normal(0, 12, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8), truth


def _box_of(truth: np.ndarray, pad: int) -> tuple[int, int, int, int]:
    ys, xs = np.nonzero(truth)
    h, w = truth.shape
    return (max(0, xs.min() - pad), max(0, ys.min() - pad), min(w, xs.max() + 1 + pad), min(h, ys.max() + 1 + pad))


@pytest.fixture
def scene():
    return _scene()


@pytest.fixture
def session(scene):
    image, truth = scene
    s = GrabCutSession(image)
    s.box(*_box_of(truth, 8))
    return s


# ------------------------------------------------------------------ footprint


def test_footprint_disk_by_hand():
    got = stroke_footprint((5, 5), [(2, 2)], 1)
    want = np.array([[0, 0, 0, 0, 0],
                     [0, 0, 1, 0, 0],
                     [0, 1, 1, 1, 0],
                     [0, 0, 1, 0, 0],
                     [0, 0, 0, 0, 0]], bool)
    np.testing.assert_array_equal(got, want)


def test_footprint_polyline_by_hand():
    # x is the column: a horizontal segment on row 1, then down column 3.
    got = stroke_footprint((4, 5), [(0, 1), (3, 1), (3, 3)], 0.5)
    want = np.array([[0, 0, 0, 0, 0],
                     [1, 1, 1, 1, 0],
                     [0, 0, 0, 1, 0],
                     [0, 0, 0, 1, 0]], bool)
    np.testing.assert_array_equal(got, want)


def test_footprint_matches_distance_definition():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-5, 45, (6, 2))
    radius = 3.7
    got = stroke_footprint((40, 50), pts, radius)
    yy, xx = np.mgrid[0:40, 0:50]
    p = np.stack([xx, yy], -1).reshape(-1, 1, 2).astype(float)
    a, b = pts[:-1][None], pts[1:][None]
    t = np.clip(((p - a) * (b - a)).sum(-1) / ((b - a) ** 2).sum(-1), 0, 1)[..., None]
    dist = np.linalg.norm(p - (a + t * (b - a)), axis=-1).min(axis=1).reshape(40, 50)
    np.testing.assert_array_equal(got, dist <= radius)


def test_footprint_outside_frame_is_empty():
    assert not stroke_footprint((10, 10), [(50, 50)], 2).any()


@pytest.mark.parametrize(("args", "name"), [
    (((10, 10), [], 2), "points"),
    (((10, 10), [(1, 1)], 0), "radius"),
    (((10, 10), [(1, 1)], -2), "radius"),
    (((10, 10), [(1, 1)], float("nan")), "radius"),
    (((10, 10), [(1, np.inf)], 2), "points"),
    (((10, 10), [(1, 2, 3)], 2), "points"),
    (((0, 10), [(1, 1)], 2), "shape"),
])
def test_footprint_bad_input(args, name):
    with pytest.raises(ValueError, match=name):
        stroke_footprint(*args)


# ---------------------------------------------------------------------- box


def test_box_recovers_object(scene):
    image, truth = scene
    box = _box_of(truth, 8)
    mask = GrabCutSession(image).box(*box)
    assert mask.dtype == bool and mask.shape == truth.shape
    assert _iou(mask, truth) > 0.9
    x0, y0, x1, y1 = box
    outside = np.ones_like(mask)
    outside[y0:y1, x0:x1] = False
    assert not mask[outside].any()


def test_box_recovers_object_640x480():
    image, truth = _scene(640, 480, seed=1)
    s = GrabCutSession(image)
    assert _iou(s.box(*_box_of(truth, 25)), truth) > 0.95
    # The ROI was scaled down: the graph cut ran at reduced resolution.
    assert max(s._guide.geom.low_w, s._guide.geom.low_h) < 480


def test_box_through_an_object_keeps_its_part_in_the_box():
    # A demo frame where a box over the left part of a frying pan once came
    # back empty: the pan goes on into the ROI's margin, so the margin's
    # colours include the pan's (see egonet.grabcut.cut._rescue).
    frame = list(synth.render_activity("cooking", 3, seed=0, width=320, height=240))[2]
    x0, y0, x1, y1 = box = (77, 82, 159, 147)
    part = np.zeros_like(frame.mask)
    part[y0:y1, x0:x1] = frame.mask[y0:y1, x0:x1]
    assert part.sum() > 0.3 * (x1 - x0) * (y1 - y0)
    session = GrabCutSession(frame.rgb)
    assert _iou(session.box(*box), part) > 0.9
    resumed = GrabCutSession.from_state(frame.rgb, session.state())
    stroke = [(120, 100), (130, 105)]
    np.testing.assert_array_equal(resumed.stroke(stroke, "bg", 3), session.stroke(stroke, "bg", 3))


def test_box_is_deterministic(scene):
    image, truth = scene
    box = _box_of(truth, 8)
    np.testing.assert_array_equal(GrabCutSession(image).box(*box), GrabCutSession(image).box(*box))


def test_new_box_starts_a_new_object(session, scene):
    image, truth = scene
    session.stroke([(5, 5)], "fg", 2)
    mask = session.box(*_box_of(truth, 8))
    assert not mask[5, 5]
    assert session.box_coords == _box_of(truth, 8)


# ------------------------------------------------------------------ strokes


@pytest.mark.parametrize(("points", "label"), [
    ([(20, 20), (60, 25)], "fg"),     # background made object
    ([(100, 75), (120, 70)], "bg"),   # object made background
    ([(100, 75)], "bg"),              # a single point paints a disk
])
def test_strokes_are_hard_constraints(session, points, label):
    radius = 4.5
    mask = session.stroke(points, label, radius)
    under = stroke_footprint(mask.shape, points, radius)
    assert under.any()
    assert (mask[under] == (label == "fg")).all()
    np.testing.assert_array_equal(session.mask, mask)


def test_later_stroke_wins_where_strokes_overlap(session):
    session.stroke([(100, 75)], "bg", 6)
    mask = session.stroke([(100, 75)], "fg", 3)
    assert mask[stroke_footprint(mask.shape, [(100, 75)], 3)].all()
    ring = stroke_footprint(mask.shape, [(100, 75)], 6) & ~stroke_footprint(mask.shape, [(100, 75)], 3)
    assert not mask[ring].any()


def test_stroke_fixes_an_error():
    # The object's bar has the colour of background clutter near the box, so
    # the box alone cuts the bar off; one fg stroke along it brings it back.
    image, truth = _scene()
    rng = np.random.default_rng(5)
    bar = truth & (np.arange(truth.shape[1]) > 146)[None, :]
    blue = np.array([50, 60, 200])
    image[bar] = np.clip(blue + rng.normal(0, 12, (bar.sum(), 3)), 0, 255)
    image[20:35, 30:60] = np.clip(blue + rng.normal(0, 12, (15, 30, 3)), 0, 255)
    s = GrabCutSession(image)
    before = s.box(*_box_of(truth, 8))
    assert before[bar].mean() < 0.5
    after = s.stroke([(150, 75), (160, 75)], "fg", 3)
    assert after[bar].mean() > 0.95
    assert _iou(after, truth) > _iou(before, truth) + 0.02


def test_fg_stroke_outside_box_grows_it(session, scene):
    _, truth = scene
    x0, y0, x1, y1 = session.box_coords
    mask = session.stroke([(x1 + 10, y1 + 5)], "fg", 3)
    assert mask[y1 + 5, x1 + 10]
    bx0, by0, bx1, by1 = session.box_coords
    assert bx1 >= x1 + 14 and by1 >= y1 + 9 and (bx0, by0) == (x0, y0)
    assert _iou(mask, truth) > 0.9


@pytest.mark.parametrize(("points", "label"), [([(20, 20)], "fg"), ([(100, 75)], "bg"),
                                             ([(130, 75), (140, 78)], "bg")])
def test_stroke_update_is_local_and_exact(session, points, label):
    # The first stroke after a box: redoing only the changed window equals
    # redoing the whole ROI (then combined the stroke's way, and kept local:
    # changes not joined to the stroke revert, ``cut._keep_connected``).
    before = session.mask
    mask = session.stroke(points, label, 3)
    full = session._full_mask(session._guide, session._now)
    grid = min(session._guide.geom.sx, session._guide.geom.sy)
    local = _keep_connected((before | full) if label == "fg" else (before & full), before,
                            *_polyline_distance_mask(mask.shape, np.asarray(points, float), 3),
                            math.ceil(_NEAR_GRID / grid), math.ceil(_STROKE_REACH / grid))
    np.testing.assert_array_equal(mask, local)


def test_strokes_only_move_the_mask_their_way():
    image, truth = _scene(seed=2)
    s = GrabCutSession(image)
    mask = s.box(*_box_of(truth, 12))
    rng = np.random.default_rng(0)
    for _ in range(6):
        x, y = rng.integers(20, 180), rng.integers(20, 130)
        label = "fg" if truth[y, x] else "bg"
        before, mask = mask, s.stroke([(x, y), (x + 6, y + 3)], label, 3)
        if label == "fg":
            assert (mask | before == mask).all()  # nothing removed
        else:
            assert (mask & before == mask).all()  # nothing added


# --------------------------------------------------------------------- undo


def test_undo_restores_each_level_exactly(session, scene):
    m0 = session.mask
    m1 = session.stroke([(20, 20), (60, 25)], "fg", 4)
    m2 = session.stroke([(100, 75)], "bg", 5)
    assert not np.array_equal(m1, m2)
    np.testing.assert_array_equal(session.undo(), m1)
    np.testing.assert_array_equal(session.undo(), m0)
    # Undo is a real state restore: the same stroke gives the same mask again.
    np.testing.assert_array_equal(session.stroke([(20, 20), (60, 25)], "fg", 4), m1)
    np.testing.assert_array_equal(session.undo(), m0)
    # Back past the box: nothing selected, no box, nothing further to undo.
    assert not session.undo().any()
    assert session.box_coords is None and not session.can_undo
    with pytest.raises(RuntimeError, match="nothing to undo"):
        session.undo()


def test_undo_levels_are_capped(scene):
    image, truth = scene
    s = GrabCutSession(image, max_undo=2)
    s.box(*_box_of(truth, 8))
    for x in (20, 30, 40):
        s.stroke([(x, 10)], "fg", 2)
    s.undo()
    s.undo()
    assert not s.can_undo
    assert s.mask[10, 20] and not s.mask[10, 30]


# -------------------------------------------------------------------- state


def _savez_round_trip(state: dict) -> dict:
    buf = io.BytesIO()
    np.savez_compressed(buf, **state)
    buf.seek(0)
    with np.load(buf) as data:
        return {k: data[k] for k in data.files}


def test_state_is_small_and_plain(session):
    session.stroke([(20, 20), (60, 25)], "fg", 4)
    state = session.state()
    assert all(isinstance(v, (np.ndarray, int, float, str)) for v in state.values())
    assert state["format"] == grabcut.STATE_FORMAT
    assert state["models"].shape[-1] == 65  # OpenCV's bgdModel/fgdModel layout
    assert sum(v.nbytes for v in state.values() if isinstance(v, np.ndarray)) < 20_000


def test_state_round_trip_resumes_identically(session, scene):
    image, _ = scene
    session.stroke([(20, 20), (60, 25)], "fg", 4)
    session.stroke([(100, 75)], "bg", 5)
    resumed = GrabCutSession.from_state(image, _savez_round_trip(session.state()))
    np.testing.assert_array_equal(resumed.mask, session.mask)
    assert resumed.box_coords == session.box_coords
    a = session.stroke([(130, 75), (150, 80)], "bg", 3)
    b = resumed.stroke([(130, 75), (150, 80)], "bg", 3)
    np.testing.assert_array_equal(a, b)
    for _ in range(4):  # undo levels travel with the state
        np.testing.assert_array_equal(session.undo(), resumed.undo())
    assert not resumed.can_undo and not session.can_undo


def test_state_round_trip_before_box(scene):
    image, _ = scene
    resumed = GrabCutSession.from_state(image, GrabCutSession(image).state())
    assert resumed.box_coords is None and not resumed.mask.any()


def test_state_round_trip_after_box_growth(session, scene):
    image, _ = scene
    x0, y0, x1, y1 = session.box_coords
    session.stroke([(x1 + 10, y1 + 5)], "fg", 3)
    resumed = GrabCutSession.from_state(image, session.state())
    np.testing.assert_array_equal(resumed.stroke([(20, 20)], "bg", 3), session.stroke([(20, 20)], "bg", 3))


def test_from_state_rejects_another_frame_or_format(session):
    other = np.zeros((100, 100, 3), np.uint8)
    with pytest.raises(ValueError, match="state"):
        GrabCutSession.from_state(other, session.state())
    state = session.state()
    state["format"] = "something else"
    with pytest.raises(ValueError, match="state"):
        GrabCutSession.from_state(np.zeros((150, 200, 3), np.uint8), state)
    state = session.state()
    del state["models"]
    with pytest.raises(ValueError, match="state"):
        GrabCutSession.from_state(np.zeros((150, 200, 3), np.uint8), state)
    for broken in (np.nan, 0.0, -1.0):  # models that are no mixtures: refused now, not at the next stroke
        state = session.state()
        state["models"][-1, 1, :5] = broken
        with pytest.raises(ValueError, match="models"):
            GrabCutSession.from_state(np.zeros((150, 200, 3), np.uint8), state)


# -------------------------------------------------------------- bad input


@pytest.mark.parametrize(("image", "name"), [
    (np.zeros((150, 200, 3), np.float32), "image"),
    (np.zeros((150, 200), np.uint8), "image"),
    (np.zeros((150, 200, 4), np.uint8), "image"),
    ([[0, 0, 0]], "image"),
])
def test_bad_image(image, name):
    with pytest.raises(ValueError, match=name):
        GrabCutSession(image)


@pytest.mark.parametrize("kwargs", [{"work_size": 8}, {"work_size": 300.5}, {"max_undo": -1}])
def test_bad_settings(scene, kwargs):
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        GrabCutSession(scene[0], **kwargs)


@pytest.mark.parametrize("box", [
    (-5, 10, 50, 60),        # outside the frame
    (10, 10, 250, 60),
    (10, 10, 50, 151),
    (50, 10, 50, 60),        # empty
    (60, 10, 50, 60),
    (0, 0, 200, 150),        # the whole frame: no background left
])
def test_bad_box(scene, box):
    with pytest.raises(ValueError, match="box"):
        GrabCutSession(scene[0]).box(*box)


def test_bad_box_coordinate_type(scene):
    with pytest.raises(ValueError, match="x1"):
        GrabCutSession(scene[0]).box(1, 2, "30", 40)


def test_stroke_before_box(scene):
    with pytest.raises(ValueError, match="box"):
        GrabCutSession(scene[0]).stroke([(10, 10)], "fg", 3)


@pytest.mark.parametrize(("points", "label", "radius", "name"), [
    ([], "fg", 3, "points"),
    ([(1, 2, 3)], "fg", 3, "points"),
    ("abc", "fg", 3, "points"),
    ([(10, 10)], "object", 3, "label"),
    ([(10, 10)], 1, 3, "label"),
    ([(10, 10)], "fg", 0, "radius"),
    ([(10, 10)], "fg", -1, "radius"),
    ([(10, 10)], "fg", "3", "radius"),
    ([(500, 500)], "fg", 3, "points"),  # misses the frame
])
def test_bad_stroke(session, points, label, radius, name):
    before = session.mask
    with pytest.raises(ValueError, match=name):
        session.stroke(points, label, radius)
    np.testing.assert_array_equal(session.mask, before)  # nothing changed


def test_bad_state_type(scene):
    with pytest.raises(ValueError, match="state"):
        GrabCutSession.from_state(scene[0], [1, 2, 3])


# ------------------------------------------------------------------- module


def test_docstring_examples_run():
    # The package and each of its modules (testmod skips re-exported names).
    modules = [grabcut] + [importlib.import_module(m.name)
                           for m in pkgutil.iter_modules(grabcut.__path__, "egonet.grabcut.")]
    runs = [doctest.testmod(m, optionflags=doctest.ELLIPSIS) for m in modules]
    result = doctest.TestResults(sum(r.failed for r in runs), sum(r.attempted for r in runs))
    assert result.failed == 0 and result.attempted > 0


def test_module_does_not_import_web_stack():
    code = "import sys, egonet.grabcut; print('flask' in sys.modules or 'sqlalchemy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_fine_cut_moves_only_a_band_along_the_coarse_edge():
    """The full grid's last box iteration: undecided only within _FINE_BAND of the coarse label's edge."""
    from egonet.grabcut import cut
    from egonet.grabcut.geometry import _Geometry

    geom = _Geometry.for_box((40, 30, 200, 150), 180, 240, 272)
    coarse = np.zeros((round(geom.low_h / 2), round(geom.low_w / 2)), bool)
    coarse[20:45, 25:60] = True
    gc = cut._upsampled_labels(geom, coarse)
    up = cv2.resize(coarse.astype(np.float32), (geom.low_w, geom.low_h)) >= 0.5
    edge_distance = np.where(up, cv2.distanceTransform(up.view(np.uint8), cv2.DIST_L2, 5),
                             cv2.distanceTransform((~up).view(np.uint8), cv2.DIST_L2, 5))
    rows, cols = geom.box_low()
    inside = np.zeros(gc.shape, bool)
    inside[rows, cols] = True
    free = gc >= cv2.GC_PR_BGD
    assert free.any() and (free <= inside).all()
    assert edge_distance[free].max() <= cut._FINE_BAND + 1
    far = inside & (edge_distance > cut._FINE_BAND + 1)
    assert far.any() and ((gc[far] == cv2.GC_FGD) == up[far]).all() and np.isin(gc[far], (cv2.GC_FGD, cv2.GC_BGD)).all()
    assert ((gc & 1).astype(bool)[inside] == up[inside]).all()  # the labels start as the coarse cut's


def test_component_likelihoods_match_the_mixture_by_hand():
    """The component-major colour and depth scores against the Gaussian density written out per pixel."""
    from egonet.grabcut import colour, depth

    rng = np.random.default_rng(3)
    x = rng.integers(0, 256, (500, 3)).astype(np.float32)
    model = colour._fit_model(x.astype(np.float64), rng)[0]
    weights, means, covs = colour._unpack_model(model)
    live = np.flatnonzero(weights > 0)
    by_hand = np.stack([-0.5 * (np.einsum("ni,ij,nj->n", x - means[k], np.linalg.inv(covs[k]), x - means[k])
                                + np.log(np.linalg.det(covs[k]))) for k in live])
    logs, got_live = colour._component_logs(model, x)
    assert (got_live == live).all()
    np.testing.assert_allclose(logs, by_hand, rtol=1e-4, atol=1e-3)
    mixture = np.log(np.exp(by_hand + np.log(weights[live])[:, None]).sum(axis=0))
    np.testing.assert_allclose(colour._costs(model, x), -mixture, rtol=1e-4, atol=1e-3)
    assert (colour._best_rows(logs) == logs.argmax(axis=0)).all()

    z = rng.uniform(0.5, 3.0, (500, 1)).astype(np.float32)
    features = np.hstack([x, z * depth._Z_SCALE])
    valid = rng.random(500) > 0.3
    dmodel = depth._first_model(features.astype(np.float64), valid, 1.0, rng)
    dw, dm, dc = depth._unpack_model(dmodel)
    scores = depth._component_scores(dmodel, features, valid)
    for n in (0, 1, 2, int(np.flatnonzero(~valid)[0])):
        dims = 4 if valid[n] else 3
        for k in np.flatnonzero(dw > 0):
            d = features[n, :dims] - dm[k, :dims]
            c = dc[k, :dims, :dims]
            expected = (np.log(dw[k]) - 0.5 * d @ np.linalg.solve(c, d) - 0.5 * np.log(np.linalg.det(c))
                        - 0.5 * dims * np.log(2 * np.pi))
            assert scores[k, n] == pytest.approx(expected, rel=1e-4, abs=1e-2)
