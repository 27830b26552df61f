"""Tests for egonet.baselines."""

import cv2
import numpy as np
import pytest

from egonet.baselines import (
    BASELINES,
    ActionObjectPrior,
    CenterPrior,
    Predictor,
    SpectralResidualSaliency,
    aop_fold_priors,
    build_baseline,
)


def frame(h=48, w=64, value=90):
    return np.full((h, w, 3), value, dtype=np.uint8)


def all_predictors():
    masks = [np.zeros((30, 40), bool), np.ones((60, 80), bool)]
    return [ActionObjectPrior.fit(masks), CenterPrior(), SpectralResidualSaliency()]


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
    aop = ActionObjectPrior.fit([a, b, c], size=(2, 3))
    # mean: [[3, 2, 1], [2, 1, 1]] / 3
    np.testing.assert_allclose(aop.prior, np.array([[3, 2, 1], [2, 1, 1]]) / 3, atol=1e-7)
    # On a frame of the grid's size the prediction is the prior itself.
    np.testing.assert_allclose(aop.predict(frame(2, 3), None), aop.prior)


def test_aop_area_resizes_masks_of_any_size():
    # A 4x4 mask covering the top-left 2x2 block, on a 2x2 grid: cell fractions.
    a = np.zeros((4, 4), bool)
    a[:2, :2] = True
    # A 2x2 mask already on the grid.
    b = np.array([[False, True], [False, False]])
    aop = ActionObjectPrior.fit(iter([a, b]), size=(2, 2))
    np.testing.assert_allclose(aop.prior, [[0.5, 0.5], [0.0, 0.0]], atol=1e-7)
    # A 4x4 mask with one pixel in each 2x2 cell covers a quarter of every cell.
    c = np.zeros((4, 4), bool)
    c[::2, ::2] = True
    np.testing.assert_allclose(ActionObjectPrior.fit([c], size=(2, 2)).prior, 0.25, atol=1e-7)


def test_aop_predict_bilinear_to_frame():
    aop = ActionObjectPrior(np.array([[0.0, 1.0]], np.float32))
    out = aop.predict(frame(3, 8), None)
    assert out.shape == (3, 8)
    assert np.all(np.diff(out, axis=1) >= 0)  # rises from left to right
    np.testing.assert_allclose(out[:, 0], 0.0)
    np.testing.assert_allclose(out[:, -1], 1.0)


def test_aop_validation():
    with pytest.raises(ValueError, match="empty"):
        ActionObjectPrior.fit([])
    with pytest.raises(ValueError, match=r"masks\[1\]"):
        ActionObjectPrior.fit([np.zeros((4, 4), bool), np.zeros((4, 4), np.uint8)])
    with pytest.raises(ValueError, match="size"):
        ActionObjectPrior.fit([np.zeros((4, 4), bool)], size=(0, 4))
    with pytest.raises(ValueError, match="prior"):
        ActionObjectPrior(np.full((2, 2), 1.5))


# --------------------------------------------------------------------------
# Centre prior.


def test_aop_needs_another_activity():
    priors = aop_fold_priors({"only": iter([np.ones((4, 4), bool)])})
    assert priors == {"only": None}
    one, two = np.zeros((4, 4), bool), np.ones((4, 4), bool)
    priors = aop_fold_priors({"a": iter([one]), "b": iter([two, two, one])})
    assert np.allclose(priors["a"].prior, 2 / 3) and np.allclose(priors["b"].prior, 0.0)


def test_aop_fold_prior_is_the_mean_of_the_other_activities_masks():
    # Three activities on a 1x2 grid; the fold of "a" averages b's and c's three masks:
    # [[1, 0], [1, 1], [0, 0]] -> [2/3, 1/3].
    left, both, none = (np.array([v], bool) for v in ([True, False], [True, True], [False, False]))
    masks = {"a": [left, left], "b": [left, both], "c": [none]}
    priors = aop_fold_priors({k: iter(v) for k, v in masks.items()}, size=(1, 2))
    np.testing.assert_allclose(priors["a"].prior, [[2 / 3, 1 / 3]], atol=1e-7)
    np.testing.assert_allclose(priors["c"].prior, [[1.0, 0.25]], atol=1e-7)
    # The same as fitting each fold on the other activities' masks directly.
    rng = np.random.default_rng(5)
    masks = {k: [rng.random((9, 12)) > 0.6 for _ in range(n)] for k, n in (("a", 2), ("b", 3), ("c", 1))}
    priors = aop_fold_priors(masks, size=(3, 4))
    for activity in masks:
        others = [m for a, ms in masks.items() if a != activity for m in ms]
        np.testing.assert_allclose(priors[activity].prior, ActionObjectPrior.fit(others, size=(3, 4)).prior, atol=1e-6)


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
    assert set(BASELINES) == {"aop", "center", "saliency"}
    assert isinstance(build_baseline("center"), CenterPrior)
    assert isinstance(build_baseline("saliency"), SpectralResidualSaliency)
    aop = build_baseline("aop", masks=[np.ones((6, 8), bool)])
    np.testing.assert_allclose(aop.prior, 1.0)
    assert isinstance(BASELINES["aop"]([np.ones((6, 8), bool)], size=(3, 4)), ActionObjectPrior)


def test_build_rejects_unknown_and_misused():
    with pytest.raises(ValueError, match="valid names: aop, center, saliency"):
        build_baseline("gbvs")
    with pytest.raises(ValueError, match="masks"):
        build_baseline("aop")
    with pytest.raises(ValueError, match="masks"):
        build_baseline("center", masks=[np.ones((2, 2), bool)])
