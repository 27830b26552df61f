"""egonet.overlay: the one heat-map renderer and the blend over a frame."""

import numpy as np
import pytest

from egonet.overlay import MAX_OPACITY, heatmap, overlay


def test_heatmap_opacity_follows_the_probability_and_is_capped():
    layer = heatmap(np.array([[0.0, 0.25, 1 / 1.4, 1.0, 2.0]]))
    assert layer[0, :, 3].tolist() == [0, round(0.25 * 1.4 * MAX_OPACITY), MAX_OPACITY, MAX_OPACITY, MAX_OPACITY]
    # turbo: low probabilities are blue, high ones red
    low, high = layer[0, 0, :3].astype(int), layer[0, 3, :3].astype(int)
    assert low[2] > low[0] and high[0] > high[2]


def test_overlay_is_the_frame_where_the_mask_is_zero_and_the_heat_map_where_it_is_high():
    rgb = np.full((4, 6, 3), 100, np.uint8)
    mask = np.zeros((4, 6), np.float32)
    mask[:, 3:] = 1.0
    out = overlay(rgb, mask)
    assert np.array_equal(out[:, :3], rgb[:, :3])
    layer = heatmap(mask)
    a = MAX_OPACITY / 255
    expected = np.clip(100 * (1 - a) + layer[0, 5, :3].astype(np.float32) * a, 0, 255).astype(np.uint8)
    assert np.array_equal(out[0, 5], expected)


def test_overlay_downscales_to_max_width_and_checks_the_frame():
    out = overlay(np.zeros((40, 80, 3), np.uint8), None, points=[(10, 10)], outline=np.ones((40, 80), bool), max_width=20)
    assert out.shape == (10, 20, 3)
    with pytest.raises(ValueError, match="rgb"):
        overlay(np.zeros((4, 4), np.uint8), None)


def test_docstring_examples_run():
    import doctest

    import egonet.overlay

    result = doctest.testmod(egonet.overlay)
    assert result.attempted >= 2 and result.failed == 0
