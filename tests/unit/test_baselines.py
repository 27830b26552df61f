"""Tests for egonet.baselines."""

import cv2
import numpy as np
import pytest

from egonet.baselines import (
    BASELINES,
    ActionObjectPrior,
    CenterPrior,
    FirstPersonMCG,
    GraphSaliency,
    HandledViewedObj,
    HandledViewedObject,
    Judd,
    Predictor,
    SalientObjectDepth,
    SpectralResidualSaliency,
    TrainingFrame,
    build_baseline,
    fit_folds,
    is_trained,
    load_baseline,
    save_baseline,
)
from egonet.baselines.fpmcg import FEATURES as FPMCG_FEATURES
from egonet.baselines.judd import FEATURES as JUDD_FEATURES
from egonet.baselines.judd import judd_features
from egonet.baselines.regions import Proposals, forest_predict, forest_state
from egonet.baselines.salobj import FEATURES as SALOBJ_FEATURES


def frame(h=48, w=64, value=90):
    return np.full((h, w, 3), value, dtype=np.uint8)


def all_predictors():
    masks = [np.zeros((30, 40), bool), np.ones((60, 80), bool)]
    return [ActionObjectPrior().fit_masks(masks), CenterPrior(), SpectralResidualSaliency(), GraphSaliency(), HandledViewedObject()]


# --------------------------------------------------------------------------
# The shared interface.


@pytest.mark.parametrize("shape", [(48, 64), (481, 641), (7, 5)])
def test_shapes_and_ranges(shape):
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, size=(*shape, 3), dtype=np.uint8)
    dhg = rng.integers(0, 256, size=(*shape, 3), dtype=np.uint8)
    for predictor in all_predictors():
        assert isinstance(predictor, Predictor)
        for d in (None, dhg):
            out = predictor.predict(rgb, d)
            assert out.shape == shape and out.dtype == np.float32
            assert out.min() >= 0.0 and out.max() <= 1.0


def test_rejects_bad_frames():
    for predictor in all_predictors():
        with pytest.raises(ValueError, match="rgb"):
            predictor.predict(np.zeros((8, 8, 3), np.float32), None)
        with pytest.raises(ValueError, match="rgb"):
            predictor.predict(np.zeros((8, 8), np.uint8), None)
        with pytest.raises(ValueError, match="dhg"):
            predictor.predict(frame(8, 8), np.zeros((8, 9, 3), np.uint8))


# --------------------------------------------------------------------------
# Action-Object Prior.


def test_aop_is_mean_of_masks_on_grid():
    a = np.array([[1, 0, 0], [1, 0, 0]], bool)
    b = np.array([[1, 1, 0], [0, 0, 0]], bool)
    c = np.array([[1, 1, 1], [1, 1, 1]], bool)
    aop = ActionObjectPrior(size=(2, 3)).fit_masks([a, b, c])
    # mean: [[3, 2, 1], [2, 1, 1]] / 3
    np.testing.assert_allclose(aop.prior_, np.array([[3, 2, 1], [2, 1, 1]]) / 3, atol=1e-7)
    # On a frame of the grid's size the prediction is the prior itself.
    np.testing.assert_allclose(aop.predict(frame(2, 3), None), aop.prior_)
    # fit(frames) learns the same from the frames' masks.
    frames = [TrainingFrame(frame(2, 3), None, m) for m in (a, b, c)]
    np.testing.assert_array_equal(ActionObjectPrior(size=(2, 3)).fit(frames).prior_, aop.prior_)


def test_aop_area_resizes_masks_of_any_size():
    # A 4x4 mask covering the top-left 2x2 block, on a 2x2 grid: cell fractions.
    a = np.zeros((4, 4), bool)
    a[:2, :2] = True
    # A 2x2 mask already on the grid.
    b = np.array([[False, True], [False, False]])
    aop = ActionObjectPrior(size=(2, 2)).fit_masks(iter([a, b]))
    np.testing.assert_allclose(aop.prior_, [[0.5, 0.5], [0.0, 0.0]], atol=1e-7)
    # A 4x4 mask with one pixel in each 2x2 cell covers a quarter of every cell.
    c = np.zeros((4, 4), bool)
    c[::2, ::2] = True
    np.testing.assert_allclose(ActionObjectPrior(size=(2, 2)).fit_masks([c]).prior_, 0.25, atol=1e-7)


def test_aop_predict_bilinear_to_frame():
    aop = ActionObjectPrior(size=(1, 2)).load_state({"prior_": np.array([[0.0, 1.0]], np.float32)})
    out = aop.predict(frame(3, 8), None)
    assert out.shape == (3, 8)
    assert np.all(np.diff(out, axis=1) >= 0)  # rises from left to right
    np.testing.assert_allclose(out[:, 0], 0.0)
    np.testing.assert_allclose(out[:, -1], 1.0)


def test_aop_validation():
    with pytest.raises(ValueError, match="empty"):
        ActionObjectPrior().fit_masks([])
    with pytest.raises(ValueError, match="at least one training frame"):
        ActionObjectPrior().fit([])
    with pytest.raises(ValueError, match=r"masks\[1\]"):
        ActionObjectPrior().fit_masks([np.zeros((4, 4), bool), np.zeros((4, 4), np.uint8)])
    with pytest.raises(ValueError, match="size"):
        ActionObjectPrior(size=(0, 4))
    with pytest.raises(ValueError, match="not fitted"):
        ActionObjectPrior().predict(frame(4, 4))
    with pytest.raises(ValueError, match="mask"):
        TrainingFrame(frame(4, 4), None, np.zeros((4, 5), bool))


# --------------------------------------------------------------------------
# Centre prior.


def fold_frames(masks_by_activity):
    return {a: (TrainingFrame(frame(*m.shape), None, m) for m in ms) for a, ms in masks_by_activity.items()}


def test_aop_needs_another_activity():
    priors = fit_folds(ActionObjectPrior, fold_frames({"only": [np.ones((4, 4), bool)]}))
    assert priors == {"only": None}
    one, two = np.zeros((4, 4), bool), np.ones((4, 4), bool)
    priors = fit_folds(ActionObjectPrior, fold_frames({"a": [one], "b": [two, two, one]}))
    assert np.allclose(priors["a"].prior_, 2 / 3) and np.allclose(priors["b"].prior_, 0.0)


def test_aop_fold_prior_is_the_mean_of_the_other_activities_masks():
    # Three activities on a 1x2 grid; the fold of "a" averages b's and c's three masks:
    # [[1, 0], [1, 1], [0, 0]] -> [2/3, 1/3].
    left, both, none = (np.array([v], bool) for v in ([True, False], [True, True], [False, False]))
    masks = {"a": [left, left], "b": [left, both], "c": [none]}
    priors = fit_folds(lambda: ActionObjectPrior(size=(1, 2)), fold_frames(masks))
    np.testing.assert_allclose(priors["a"].prior_, [[2 / 3, 1 / 3]], atol=1e-7)
    np.testing.assert_allclose(priors["c"].prior_, [[1.0, 0.25]], atol=1e-7)
    # The same as fitting each fold on the other activities' masks directly; only the folds asked for.
    rng = np.random.default_rng(5)
    masks = {k: [rng.random((9, 12)) > 0.6 for _ in range(n)] for k, n in (("a", 2), ("b", 3), ("c", 1))}
    priors = fit_folds(lambda: ActionObjectPrior(size=(3, 4)), fold_frames(masks), folds=["a", "c"])
    assert set(priors) == {"a", "c"}
    for activity in priors:
        others = [m for a, ms in masks.items() if a != activity for m in ms]
        np.testing.assert_allclose(priors[activity].prior_, ActionObjectPrior(size=(3, 4)).fit_masks(others).prior_, atol=1e-6)


def test_saved_state_is_plain_data_and_round_trips(tmp_path):
    aop = ActionObjectPrior(size=(3, 4)).fit_masks([np.eye(3, 4, dtype=bool)])
    save_baseline(aop, tmp_path / "aop.npz")
    with np.load(tmp_path / "aop.npz", allow_pickle=False) as data:  # no pickle anywhere
        assert sorted(data.files) == ["meta", "state.prior_"]
    back = load_baseline(ActionObjectPrior, tmp_path / "aop.npz")
    assert back.size == (3, 4)
    np.testing.assert_array_equal(back.predict(frame(6, 8)), aop.predict(frame(6, 8)))
    with pytest.raises(ValueError, match="CenterPrior version"):
        load_baseline(type("CenterPrior", (ActionObjectPrior,), {}), tmp_path / "aop.npz")
    with pytest.raises(ValueError, match="not a saved baseline"):
        load_baseline(ActionObjectPrior, b"garbage")


def test_center_prior_peaks_at_centre():
    out = CenterPrior().predict(frame(49, 65), None)
    assert np.unravel_index(np.argmax(out), out.shape) == (24, 32)
    assert out[24, 32] == pytest.approx(1.0)
    # Isotropic: equal distances give equal values.
    assert out[24, 32 + 10] == pytest.approx(out[24 + 10, 32], rel=1e-6)
    # Decreasing away from the centre.
    assert out[24, 40] > out[24, 50] > out[24, 64]


def test_center_prior_sigma_is_fraction_of_diagonal():
    h, w = 30, 40  # diagonal 50
    out = CenterPrior(sigma=0.2).predict(frame(h, w), None)  # s = 10 px
    # The centre is at (row 14.5, column 19.5): pixel (14, 9) is dy 0.5, dx 10.5 away.
    d2 = 0.5**2 + 10.5**2
    assert out[14, 9] == pytest.approx(np.exp(-d2 / (2 * 10.0**2)), rel=1e-6)
    with pytest.raises(ValueError, match="sigma"):
        CenterPrior(sigma=0.0)


# --------------------------------------------------------------------------
# Spectral-residual saliency.


def test_saliency_highlights_bright_blob():
    img = frame(120, 160, value=100)
    cv2.circle(img, (110, 40), 10, (255, 255, 255), -1)  # centre x=110, y=40
    out = SpectralResidualSaliency().predict(img, None)
    y, x = np.unravel_index(np.argmax(out), out.shape)
    assert abs(y - 40) <= 12 and abs(x - 110) <= 12
    assert out[30:51, 100:121].mean() > 5 * out.mean()
    assert 0.9 < out.max() <= 1.0  # normalised at the working size, then resized


def test_saliency_uniform_frame_is_zero():
    for value in (0, 100, 255):
        out = SpectralResidualSaliency().predict(frame(60, 80, value=value), None)
        np.testing.assert_array_equal(out, 0.0)


def test_saliency_validation():
    with pytest.raises(ValueError, match="width"):
        SpectralResidualSaliency(width=4)
    with pytest.raises(ValueError, match="blur_sigma"):
        SpectralResidualSaliency(blur_sigma=-1.0)


# --------------------------------------------------------------------------
# Registry.


def test_registry_and_build():
    assert {"aop", "center", "saliency", "gbvs", "handled"} <= set(BASELINES)
    assert all(cls.name and cls.version >= 1 for cls in BASELINES.values())
    assert BASELINES["aop"].name == "AOP" and BASELINES["gbvs"].name == "GBVS"
    assert isinstance(build_baseline("center"), CenterPrior)
    assert isinstance(build_baseline("gbvs"), GraphSaliency)
    assert isinstance(build_baseline("handled"), HandledViewedObj) and is_trained("handled")
    assert isinstance(build_baseline("saliency"), SpectralResidualSaliency)
    assert build_baseline("aop", size=(3, 4)).size == (3, 4)
    assert is_trained("aop") and not is_trained("gbvs") and not is_trained("center")


def test_build_rejects_unknown_and_misused():
    with pytest.raises(ValueError, match=r"valid names: .*aop \(AOP\)"):
        build_baseline("nope")
    with pytest.raises(ValueError, match="masks"):
        build_baseline("center", masks=[np.ones((2, 2), bool)])


# --------------------------------------------------------------------------
# GBVS (Harel, Koch & Perona 2006).


def test_gbvs_equilibria_match_power_iteration():
    # The closed forms (reversible chains) against an independent computation:
    # iterate the Markov matrix built from the paper's edge weights.
    from egonet.saliency import _distance_kernel, activation_equilibrium, normalization_equilibrium

    rng = np.random.default_rng(2)
    kernel = _distance_kernel(4, 5, 0.15 * 5)
    values = rng.random(20)

    def power(weights):
        markov = weights / weights.sum(axis=1, keepdims=True)  # row i: transitions out of node i
        p = np.full(len(weights), 1.0 / len(weights))
        for _ in range(5000):
            p = p @ markov
        return p

    activation = activation_equilibrium(values, kernel)
    np.testing.assert_allclose(activation, power(np.abs(values[:, None] - values[None, :]) * kernel), atol=1e-9)
    np.testing.assert_allclose(normalization_equilibrium(activation, kernel), power(activation[None, :] * kernel), atol=1e-9)


def test_gbvs_activation_by_hand():
    # Three nodes in a row, one unlike the other two: weights |M_i - M_j| F, with F = 1 (huge sigma).
    from egonet.saliency import activation_equilibrium

    ones = np.ones((3, 3))
    # node 2 differs by 1 from nodes 0 and 1: degrees (1, 1, 2) -> (0.25, 0.25, 0.5)
    np.testing.assert_allclose(activation_equilibrium(np.array([0.0, 0.0, 1.0]), ones), [0.25, 0.25, 0.5])
    np.testing.assert_allclose(activation_equilibrium(np.zeros(3), ones), [1 / 3] * 3)  # flat: uniform


def test_gbvs_peaks_on_the_odd_one_out_and_is_symmetric():
    rgb = frame(48, 64, 128)
    rgb[20:28, 28:36] = (230, 30, 30)  # a red square in the middle of gray
    s = GraphSaliency().predict(rgb)
    assert s.max() == 1.0 and s.min() == 0.0
    y, x = np.unravel_index(int(np.argmax(s)), s.shape)
    assert 18 <= y <= 29 and 26 <= x <= 37
    assert s[20:28, 28:36].mean() > 3 * s[:8].mean()
    np.testing.assert_allclose(s, s[:, ::-1], atol=1e-4)  # a symmetric frame gives a symmetric map
    assert not GraphSaliency().predict(frame()).any()  # a uniform frame: no saliency


def test_gbvs_options_are_checked():
    for options, field in [({"grid_width": 2}, "grid_width"), ({"levels": ()}, "levels"), ({"sigma_activation": 0}, "sigma_activation"),
                           ({"blur": 2}, "blur")]:
        with pytest.raises(ValueError, match=field):
            GraphSaliency(**options)


def test_gbvs_on_real_frames_finds_the_chair():
    from egonet import io
    from tests.realdata import EGONET_SAMPLES, PRIMESENSE, chair_truth

    if not PRIMESENSE.exists():
        pytest.skip("the shared real frames are absent")
    chair = chair_truth()
    s = GraphSaliency().predict(io.read_image(PRIMESENSE / "color" / "00001.jpg"))
    assert s.shape == chair.shape
    assert s[chair].mean() > 1.5 * s[~chair].mean()  # measured 0.55 against 0.32
    for path in sorted((EGONET_SAMPLES / "rgb").iterdir())[:2]:
        out = GraphSaliency().predict(io.read_image(path))
        assert out.dtype == np.float32 and 0.1 < out.mean() < 0.6 and out.max() == 1.0


# --------------------------------------------------------------------------
# Handled + viewed object.


def two_objects():
    rgb = frame(96, 128, 200)
    rgb[40:56, 56:72] = (200, 40, 40)  # at the centre
    rgb[4:20, 4:20] = (40, 40, 200)  # top-left corner
    return rgb


def test_handled_viewed_takes_the_object_nearest_the_centre_without_hands():
    p = HandledViewedObject().predict(two_objects())
    assert p[48, 64] == pytest.approx(1.0)
    assert 0 < p[12, 12] < 0.1  # the corner object: exp(-d^2 / 2 sigma^2), d ~ 0.35 of the diagonal
    assert p[90, 120] == 0.0  # the background is no object region (too large)


def test_handled_viewed_prefers_the_object_nearest_the_hands_and_skips_the_hands():
    rgb = two_objects()
    hand = np.zeros(rgb.shape[:2], bool)
    hand[20:30, 4:20] = True  # just below the corner object
    rgb[hand] = (230, 180, 150)  # skin
    p = HandledViewedObject().predict(rgb, near=hand, exclude=hand)
    assert p[12, 12] > 0.9 and p[12, 12] > p[48, 64]
    assert p[25, 10] == 0.0  # the hand itself is not the object
    # Whatever mask is "near" (here the centre object itself): that object wins.
    held = np.zeros_like(hand)
    held[40:56, 56:72] = True
    assert HandledViewedObject().predict(rgb, near=held)[48, 64] == pytest.approx(1.0)


def hand_frame(corner: int):
    """``two_objects`` with the corner object at column ``corner`` held by a skin-coloured arm from the bottom edge; the arm's mask."""
    rgb = frame(96, 128, 200)
    rgb[40:56, 56:72] = (200, 40, 40)  # at the centre
    rgb[4:20, corner : corner + 16] = (40, 40, 200)
    hand = np.zeros(rgb.shape[:2], bool)
    hand[20:, corner : corner + 16] = True
    rgb[hand] = (205, 145, 115)
    return rgb, hand


def test_the_learned_handled_row_finds_the_hands_itself_and_takes_the_object_they_hold():
    # Trained on frames whose hands are labelled (instances "hand"), never told where the scored frame's hands are.
    training = [TrainingFrame(*hand_frame(c)[:1], None, np.zeros((96, 128), bool), (("Hand", hand_frame(c)[1]),))
                for c in (4, 20, 36, 84, 100)]  # fmt: skip
    model = HandledViewedObj(hand_width=128, pixels_per_frame=4000).fit(training)
    assert model.hands == "learned, 5 frames"
    rgb, hand = hand_frame(108)  # a corner no training frame had
    np.testing.assert_array_equal(model.detect_hands(rgb), hand)
    p = model.predict(rgb)
    assert p[12, 116] > 0.9 and p[12, 116] > p[48, 64]  # the object the hand holds, not the centre's
    assert p[25, 116] < 0.02  # the hand is no object: only the floor (a fiftieth of the centre prior)
    # No hands in view: the object nearest the centre, as the paper's fallback.
    assert model.predict(two_objects())[48, 64] == pytest.approx(1.0)
    # Its state is plain arrays and gives back the same maps.
    again = HandledViewedObj(hand_width=128, pixels_per_frame=4000).load_state(model.state())
    np.testing.assert_array_equal(again.predict(rgb), p)
    assert again.hands == "learned, 5 frames"


def test_without_hand_labels_the_handled_row_falls_back_on_skin_colour():
    rgb, hand = hand_frame(108)
    model = HandledViewedObj().fit([TrainingFrame(rgb, None, np.zeros((96, 128), bool))])
    assert model.hands == "skin colour"
    np.testing.assert_array_equal(model.detect_hands(rgb), hand)  # this hand is plainly skin-coloured
    with pytest.raises(ValueError, match="hand_threshold must be in"):
        HandledViewedObj(hand_threshold=1.5)


def test_handled_viewed_checks_its_masks():
    with pytest.raises(ValueError, match="near must be None or a bool"):
        HandledViewedObject().predict(two_objects(), near=np.zeros((4, 4), bool))
    with pytest.raises(ValueError, match="max_area"):
        HandledViewedObject(min_area=0.5, max_area=0.1)


# --------------------------------------------------------------------------
# The learned baselines of Table 2: Judd, FP-MCG, salObj+depth, and the protocol they share.


def square_frames(n=4, size=(48, 64), seed=0, dhg=False):
    """Frames of a grey, mildly noisy room with a blue square (the action-object) somewhere, and a red distractor strip."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        rgb = np.clip(rng.normal(170, 6, (*size, 3)), 0, 255).astype(np.uint8)
        r, c = rng.integers(4, size[0] - 20), rng.integers(4, size[1] - 20)
        mask = np.zeros(size, bool)
        mask[r : r + 14, c : c + 14] = True
        rgb[mask] = (30, 40, 200)
        rgb[size[0] - 4 :, :] = (200, 40, 40)
        d = None
        if dhg:
            d = np.zeros((*size, 3), np.uint8)
            d[..., 2] = np.where(mask, 40, 120)  # the object is nearer
            d[..., 1] = np.where(mask, 110, 30)  # and higher above the floor
        out.append(TrainingFrame(rgb, d, mask))
    return out


LEARNED = {"judd": Judd(work_width=64), "fpmcg": FirstPersonMCG(work_width=64, trees=8), "salobj": SalientObjectDepth(work_width=64, trees=8)}


@pytest.mark.parametrize("key", sorted(LEARNED))
def test_each_learned_baseline_finds_the_kind_of_object_it_was_trained_on(key, tmp_path):
    train, test = square_frames(6, seed=1, dhg=True), square_frames(2, seed=2, dhg=True)
    model = type(LEARNED[key])(**LEARNED[key].params()).fit(train)
    for frame in test:
        p = model.predict(frame.rgb, frame.dhg)
        assert p.shape == frame.mask.shape and p.dtype == np.float32 and 0 <= p.min() and p.max() <= 1
        assert p[frame.mask].mean() > p[~frame.mask].mean() + 0.3, key  # the object, not the room or the red strip
    # What was fitted is plain data, and comes back the same.
    save_baseline(model, tmp_path / f"{key}.npz")
    back = load_baseline(type(model), tmp_path / f"{key}.npz")
    for frame in test:
        np.testing.assert_array_equal(back.predict(frame.rgb, frame.dhg), model.predict(frame.rgb, frame.dhg))
    with pytest.raises(ValueError, match="not fitted"):
        type(model)().predict(test[0].rgb)


def test_the_forest_is_kept_as_arrays_that_predict_as_scikit_learn_does():
    from sklearn.ensemble import RandomForestRegressor
    from sklearn.tree import DecisionTreeRegressor

    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 5)).astype(np.float32)
    y = np.sin(x[:, 0]) + x[:, 1] ** 2 + rng.normal(0, 0.1, 300)
    test = rng.normal(size=(100, 5)).astype(np.float32)
    for model in (RandomForestRegressor(n_estimators=7, max_depth=6, random_state=0).fit(x, y), DecisionTreeRegressor(max_depth=4).fit(x, y)):
        np.testing.assert_allclose(forest_predict(forest_state(model), test), model.predict(test), rtol=0, atol=1e-12)
    # By hand: one stump, x <= 0.5 goes left (value 1), else right (value 3); two stumps average.
    stump = {"left": np.array([1, -1, -1, 4, -1, -1]), "right": np.array([2, -1, -1, 5, -1, -1]),
             "feature": np.array([0, 0, 0, 1, 0, 0]), "threshold": np.array([0.5, 0, 0, 0.0, 0, 0]),
             "value": np.array([0, 1.0, 3.0, 0, 10.0, 20.0]), "roots": np.array([0, 3])}  # fmt: skip
    assert forest_predict(stump, np.array([[0.5, -1.0], [0.6, 1.0]])).tolist() == [5.5, 11.5]


def test_proposal_statistics_by_hand():
    # Two levels on a 2x4 grid: level 0 has regions 0 | 1 | 2 (columns 0, 1, 2-3), level 1 merges 1 and 2.
    fine = np.array([[0, 1, 2, 2], [0, 1, 2, 2]], np.int32)
    coarse = np.array([[0, 1, 1, 1], [0, 1, 1, 1]], np.int32)
    values = np.array([[1.0, 2.0, 3.0, 5.0], [1.0, 4.0, np.nan, 5.0]])
    props = Proposals([fine, coarse], np.array([0, 3]), np.zeros((2, 4)), np.zeros((2, 4, 3), np.uint8), None, None)
    assert props.n == 5
    np.testing.assert_array_equal(props.area(), [2, 2, 4, 2, 6])
    np.testing.assert_allclose(props.mean(values), [1, 3, 13 / 3, 1, 19 / 5])
    np.testing.assert_allclose(props.median(values), [1, 3, 5, 1, 4])
    # Neighbours in the same level, weighted by shared border: fine region 1 touches 0 and 2 along 2 pixels each.
    np.testing.assert_allclose(props.surround(np.array([10.0, 20, 30, 40, 50])), [20, 20, 20, 50, 40])
    shape = props.shape()  # area share, centroid x and y, bbox width and height, fill
    np.testing.assert_allclose(shape[2], [4 / 8, 2.5 / 4, 0.5 / 2, 2 / 4, 2 / 2, 1.0])
    np.testing.assert_allclose(props.spread(np.array([0.1, 0.9, 0.2, 0.3, 0.4])), [[0.3, 0.9, 0.4, 0.4]] * 2)


def test_judd_features_by_hand():
    rgb = np.zeros((40, 40, 3), np.uint8)
    rgb[:, 30:] = (255, 0, 0)  # a quarter of the frame is red, the rest black
    f = judd_features(rgb, work_width=40)
    assert f.shape == (40, 40, len(JUDD_FEATURES))
    col = {name: f[..., i] for i, name in enumerate(JUDD_FEATURES)}
    np.testing.assert_allclose(col["red"][0, 35], 1.0) and np.testing.assert_allclose(col["red"][0, 5], 0.0)
    np.testing.assert_allclose(col["colour rarity median 1"][0, 35], -np.log(0.25 + 1e-6), rtol=1e-5)
    np.testing.assert_allclose(col["colour rarity median 1"][0, 5], -np.log(0.75 + 1e-6), rtol=1e-5)
    np.testing.assert_allclose(col["row y"][:, 0], (np.arange(40) + 0.5) / 40, rtol=1e-6)
    assert col["distance to centre"][19:21, 19:21].max() < 0.05 and col["distance to centre"][0, 0] > 0.9
    assert not col["faces"].any()  # no face in a flat frame


def test_judd_draws_its_samples_inside_and_outside_the_mask():
    frame = square_frames(1)[0]
    summary = Judd(work_width=64, samples=10).summarize(frame)
    assert summary["x"].shape == (20, len(JUDD_FEATURES)) and summary["y"].sum() == 10
    assert (summary["x"][summary["y"], JUDD_FEATURES.index("blue")] > 0.7).all()  # the square's pixels are blue
    with pytest.raises(ValueError, match="inside and outside"):
        Judd().fit_summaries([{"x": summary["x"][summary["y"]], "y": summary["y"][summary["y"]]}])


def test_region_regressors_learn_the_overlap_of_each_proposal():
    frame = square_frames(1)[0]
    summary = FirstPersonMCG(work_width=64).summarize(frame)
    assert summary["x"].shape[1] == len(FPMCG_FEATURES) and np.isnan(summary["x"][:, -2:]).all()  # no DHG: no depth
    assert summary["y"].max() > 0.95  # the flat square is a region of the hierarchy (up to a pixel of its blurred edge)
    assert 0 <= summary["y"].min()
    with_depth = SalientObjectDepth(work_width=64).summarize(square_frames(1, dhg=True)[0])
    assert with_depth["x"].shape[1] == len(SALOBJ_FEATURES) and np.isfinite(with_depth["x"][:, -3:]).all()


def test_learned_baselines_check_their_settings():
    for bad, field in ((lambda: Judd(samples=0), "samples"), (lambda: Judd(C=0), "C"), (lambda: FirstPersonMCG(levels=(0.5, 0.2)), "levels"),
                       (lambda: SalientObjectDepth(trees=0), "trees"), (lambda: FirstPersonMCG(work_width=True), "work_width")):  # fmt: skip
        with pytest.raises(ValueError) as info:
            bad()
        assert info.value.field == field
