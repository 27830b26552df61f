"""Tests for egonet.clicks: superpixels and click -> soft mask."""

import math

import numpy as np
import pytest

from egonet.clicks import SUPERPIXEL_DEFAULTS, boundary_strength, click_gaussian, project_to_regions, regions, soft_mask, superpixels


def stripes(h=8, w=8, n=4):
    """Labels of n vertical stripes, int32 (h, w)."""
    return np.repeat(np.arange(n, dtype=np.int32), w // n)[None, :].repeat(h, axis=0)


def smooth_image(h=48, w=64, seed=0):
    """Low-frequency colour blobs: something SLIC can segment into many regions."""
    import cv2

    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, size=(4, 5, 3), dtype=np.uint8)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


def two_colour_image(h=60, w=80):
    img = np.zeros((h, w, 3), dtype=np.uint8)
    img[:, w // 2 :] = (250, 240, 230)
    img[:, : w // 2] = (10, 20, 30)
    return img


# --------------------------------------------------------------------------
# soft_mask: hand-checkable cases.


def test_hand_example_one_row():
    # Click at (x=0, y=0), sigma 1, three pixels in one row: raw Gaussian
    # [1, e^-0.5, e^-2]; regions [0, 1, 1] -> [1, (e^-0.5 + e^-2) / 2, same].
    labels = np.array([[0, 1, 1]], dtype=np.int32)
    out = soft_mask((1, 3), [(0.0, 0.0)], sigma=1.0, labels=labels)
    mean = (math.exp(-0.5) + math.exp(-2.0)) / 2
    np.testing.assert_allclose(out, [[1.0, mean, mean]], rtol=1e-6)
    assert out.dtype == np.float32


def test_region_constant_and_click_region_largest():
    labels = stripes(8, 8, 4)
    out = soft_mask((8, 8), [(5.0, 3.0)], sigma=3.0, labels=labels)  # column 5 is in stripe 2
    for r in range(4):
        region = out[labels == r]
        assert np.all(region == region[0])
    region_values = [out[labels == r][0] for r in range(4)]
    assert int(np.argmax(region_values)) == 2
    assert 0.0 < out.min() and out.max() <= 1.0


def test_no_clicks_gives_zeros():
    labels = stripes()
    for clicks in ([], np.zeros((0, 2))):
        out = soft_mask((8, 8), clicks, labels=labels)
        assert out.shape == (8, 8) and out.dtype == np.float32
        np.testing.assert_array_equal(out, 0.0)
    np.testing.assert_array_equal(soft_mask((8, 8), [], labels=None), 0.0)


def test_larger_sigma_spreads_further():
    labels = stripes(8, 8, 4)
    narrow = soft_mask((8, 8), [(0.0, 4.0)], sigma=2.0, labels=labels)
    wide = soft_mask((8, 8), [(0.0, 4.0)], sigma=8.0, labels=labels)
    far = labels == 3
    assert np.all(wide[far] > narrow[far])


def test_two_clicks_are_max_before_projection():
    labels = stripes(8, 8, 2)
    c1, c2 = (1.0, 1.0), (6.0, 6.0)
    both = soft_mask((8, 8), [c1, c2], sigma=2.0, labels=labels)
    g = np.maximum(click_gaussian((8, 8), [c1], sigma=2.0), click_gaussian((8, 8), [c2], sigma=2.0))
    np.testing.assert_array_equal(both, project_to_regions(g, labels))
    np.testing.assert_array_equal(click_gaussian((8, 8), [c1, c2], sigma=2.0), g)


def test_one_region_per_pixel_equals_raw_gaussian():
    h, w = 9, 13
    labels = np.arange(h * w, dtype=np.int32).reshape(h, w)
    clicks = [(3.0, 4.0), (10.5, 1.25)]
    projected = soft_mask((h, w), clicks, sigma=2.5, labels=labels)
    raw = soft_mask((h, w), clicks, sigma=2.5, labels=None)
    np.testing.assert_array_equal(projected, raw)
    rows, cols = np.mgrid[0:h, 0:w]
    expected = np.max(
        [np.exp(-((cols - x) ** 2 + (rows - y) ** 2) / (2 * 2.5**2)) for x, y in clicks],
        axis=0,
    )
    np.testing.assert_allclose(raw, expected, rtol=1e-6, atol=1e-7)
    assert raw[4, 3] == 1.0  # peak 1 at the click


def test_click_on_frame_edge_accepted():
    out = soft_mask((4, 6), [(-0.5, -0.5), (5.5, 3.5)], sigma=1.0, labels=None)
    assert out.shape == (4, 6)


def test_project_to_regions_non_contiguous_and_unsigned_labels():
    values = np.array([[1.0, 3.0, 5.0, 7.0]], dtype=np.float32)
    for dtype in (np.int64, np.uint16, np.uint64):
        labels = np.array([[10, 10, 3, 3]], dtype=dtype)
        np.testing.assert_array_equal(project_to_regions(values, labels), [[2.0, 2.0, 6.0, 6.0]])


# --------------------------------------------------------------------------
# soft_mask: validation.


def test_soft_mask_validation():
    labels = stripes()
    with pytest.raises(ValueError, match="labels has shape"):
        soft_mask((8, 9), [(1, 1)], labels=labels)
    with pytest.raises(ValueError, match="sigma"):
        soft_mask((8, 8), [(1, 1)], sigma=0.0, labels=labels)
    with pytest.raises(ValueError, match="sigma"):
        soft_mask((8, 8), [(1, 1)], sigma=float("nan"), labels=labels)
    with pytest.raises(ValueError, match=r"clicks\[1\].*outside"):
        soft_mask((8, 8), [(1, 1), (8.0, 2.0)], labels=labels)
    with pytest.raises(ValueError, match=r"clicks\[0\].*outside"):
        soft_mask((8, 8), [(1.0, -1.0)], labels=labels)
    with pytest.raises(ValueError, match=r"clicks\[2\].*not finite"):
        soft_mask((8, 8), [(1, 1), (2, 2), (float("nan"), 3)], labels=labels)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        soft_mask((8, 8), (3.0, 4.0), labels=labels)  # one click not wrapped in a list
    with pytest.raises(ValueError, match="shape"):
        soft_mask((8, 0), [], labels=None)
    with pytest.raises(ValueError, match="integer"):
        soft_mask((8, 8), [(1, 1)], labels=labels.astype(np.float32))
    with pytest.raises(ValueError, match="non-negative"):
        soft_mask((8, 8), [(1, 1)], labels=labels - 1)
    with pytest.raises(TypeError):
        soft_mask((8, 8), [(1, 1)])  # labels must be given, None included


# --------------------------------------------------------------------------
# superpixels.


FEW_REGIONS = {"slic": {"n_segments": 30}, "felzenszwalb": {"scale": 20.0}, "hierarchical": {"fine_regions": 150, "level": 0.2}}


@pytest.mark.parametrize("method", ["slic", "felzenszwalb", "hierarchical"])
def test_superpixels_labels_contiguous(method):
    img = smooth_image(48, 64)
    labels = superpixels(img, method=method, **FEW_REGIONS[method])
    assert labels.shape == (48, 64) and labels.dtype == np.int32
    n = int(labels.max()) + 1
    assert n > 3
    np.testing.assert_array_equal(np.unique(labels), np.arange(n))


@pytest.mark.parametrize("method", ["slic", "felzenszwalb", "hierarchical"])
@pytest.mark.parametrize("max_side", [None, 32])
def test_superpixels_follow_colour_boundary(method, max_side):
    img = two_colour_image(60, 80)
    options = {"fine_regions": 150} if method == "hierarchical" else {}
    labels = superpixels(img, method=method, max_side=max_side, **options)
    assert labels.shape == (60, 80)
    left, right = set(np.unique(labels[:, :40])), set(np.unique(labels[:, 40:]))
    assert not left & right


def test_superpixels_n_segments_controls_count():
    img = smooth_image(60, 80, seed=1)
    few = superpixels(img, method="slic", n_segments=4).max() + 1
    many = superpixels(img, method="slic", n_segments=100).max() + 1
    assert few < many


def test_hierarchical_level_cuts_the_hierarchy():
    img = smooth_image(60, 80, seed=2)
    counts = [int(superpixels(img, level=level, fine_regions=150).max()) + 1 for level in (0.05, 0.3, 1.5)]
    assert counts[0] > counts[1] > counts[2]
    fine = superpixels(img, level=1e-9, fine_regions=120)
    assert 60 <= fine.max() + 1 <= 130  # nothing merged: the watershed's own regions
    # Merging only joins regions: every coarse region is a union of finer ones.
    coarse, finer = superpixels(img, level=0.5, fine_regions=150), superpixels(img, level=0.2, fine_regions=150)
    for r in np.unique(finer):
        assert len(np.unique(coarse[finer == r])) == 1


def test_hierarchical_regions_stop_at_an_object_boundary():
    img = smooth_image(60, 80, seed=3) // 4 + 90
    yy, xx = np.mgrid[:60, :80]
    disc = (xx - 50) ** 2 + (yy - 30) ** 2 < 12**2
    img[disc] = (230, 40, 40)
    labels = superpixels(img, max_side=None, fine_regions=60)
    inside, outside = set(np.unique(labels[disc])), set(np.unique(labels[~disc]))
    assert not inside & outside
    clicked = labels == labels[30, 50]
    assert clicked[disc].mean() > 0.5  # the clicked region is most of the object
    out = soft_mask((60, 80), [(50.0, 30.0)], sigma=15.0, labels=labels)
    assert out[clicked].min() > out[~disc].max()


def test_boundary_strength_is_relative_and_peaks_on_edges():
    img = two_colour_image(40, 60)
    strength = boundary_strength(img)
    assert strength.shape == (40, 60) and strength.min() >= 0
    assert strength[:, 28:32].mean() > 10 * strength[:, :20].mean()
    np.testing.assert_allclose(boundary_strength(img // 2 + 20)[:, 28:32], strength[:, 28:32], rtol=0.35)
    assert SUPERPIXEL_DEFAULTS.method == "hierarchical"


def test_a_flat_frame_is_one_or_few_regions_without_the_cap_and_none_over_it_with_it():
    flat = np.full((30, 40, 3), 128, np.uint8)
    labels = superpixels(flat, fine_regions=100, max_region_share=1.0)
    assert labels.shape == (30, 40) and labels.min() == 0 and labels.max() < 5
    capped = regions(flat, fine_regions=100)  # nothing to merge along: it falls to the watershed regions
    assert np.bincount(capped.labels.ravel()).max() <= SUPERPIXEL_DEFAULTS.max_region_share * 30 * 40
    assert capped.capped.tolist() == list(range(capped.labels.max() + 1))  # every region stands where the cap split one


def test_superpixels_validation():
    img = two_colour_image()
    with pytest.raises(ValueError, match="valid methods: hierarchical, slic, felzenszwalb"):
        superpixels(img, method="mcg")
    with pytest.raises(ValueError, match="scale does not apply"):
        superpixels(img, method="slic", scale=50.0)
    with pytest.raises(ValueError, match="n_segments does not apply"):
        superpixels(img, method="felzenszwalb", n_segments=10)
    with pytest.raises(ValueError, match="level does not apply"):
        superpixels(img, method="slic", level=0.3)
    with pytest.raises(ValueError, match="n_segments"):
        superpixels(img, method="slic", n_segments=0)
    with pytest.raises(ValueError, match="level must be a positive number"):
        superpixels(img, level=float("nan"))
    with pytest.raises(ValueError, match="fine_regions must be a positive int"):
        superpixels(img, fine_regions=2.5)
    with pytest.raises(ValueError, match="image"):
        superpixels(img.astype(np.float32))
    with pytest.raises(ValueError, match="image"):
        superpixels(img[:, :, 0])
    with pytest.raises(ValueError, match="max_side"):
        superpixels(img, max_side=2)


def test_superpixels_feed_soft_mask():
    img = two_colour_image(60, 80)
    labels = superpixels(img, method="slic", n_segments=12)
    out = soft_mask((60, 80), [(60.0, 30.0)], sigma=10.0, labels=labels)
    for r in np.unique(labels):
        assert np.ptp(out[labels == r]) == 0
    assert out[:, 40:].mean() > 10 * out[:, :40].mean()


def test_the_region_cap_falls_to_a_finer_level_only_where_a_region_is_too_large():
    # Two grey halves with a weak boundary between them, and a white square: at the default level the halves merge.
    img = np.full((80, 80, 3), 100, np.uint8)
    img[:, 40:] = 125
    img[5:15, 5:15] = 255
    whole = regions(img, fine_regions=200, max_region_share=1.0)
    sizes = np.bincount(whole.labels.ravel())
    assert sizes.max() > 0.98 * 80 * 80 and len(whole.capped) == 0
    big = whole.labels == sizes.argmax()

    capped = regions(img, fine_regions=200, max_region_share=0.6)
    assert np.bincount(capped.labels.ravel()).max() <= 0.6 * 80 * 80
    assert capped.labels[40, 20] != capped.labels[40, 60]  # split along the weak boundary: the next level down
    assert len(np.unique(capped.labels[40:, :38])) == 1 and len(np.unique(capped.labels[40:, 42:])) == 1
    np.testing.assert_array_equal(capped.labels == capped.labels[10, 10], whole.labels == whole.labels[10, 10])  # the square as it was
    np.testing.assert_array_equal(np.isin(capped.labels, capped.capped), big)  # the capped ids are the split region's pixels

    finer = regions(img, fine_regions=200, max_region_share=0.3)  # halves over the cap too: down to the watershed
    assert np.bincount(finer.labels.ravel()).max() <= 0.3 * 80 * 80


def test_the_region_cap_is_checked():
    img = np.zeros((20, 20, 3), np.uint8)
    for bad in (0.0, 1.5, float("nan"), True):
        with pytest.raises(ValueError, match="max_region_share"):
            regions(img, max_region_share=bad)
    with pytest.raises(ValueError, match="max_region_share does not apply"):
        regions(img, method="slic", max_region_share=0.5)
    assert len(regions(img, method="slic", n_segments=4).capped) == 0


def test_points_mask_is_the_union_of_discs_of_radius_sigma():
    from egonet.clicks import points_mask, scaled_sigma
    from egonet.errors import EgonetError

    m = points_mask((5, 7), [(3.0, 2.0)], sigma=1.0)  # by hand: the point and its four neighbours
    expected = np.zeros((5, 7), bool)
    expected[2, 2:5] = expected[1:4, 3] = True
    assert np.array_equal(m, expected)
    rows, cols = np.mgrid[:40, :50]
    points = [(10.0, 10.0), (33.5, 20.25)]
    direct = np.zeros((40, 50), bool)
    for x, y in points:
        direct |= (cols - x) ** 2 + (rows - y) ** 2 <= 7.3**2
    assert np.array_equal(points_mask((40, 50), points, sigma=7.3), direct)
    assert not points_mask((40, 50), [], sigma=3).any()
    assert scaled_sigma(1280) == 60.0 and scaled_sigma(640) == 30.0
    with pytest.raises(EgonetError, match="lies outside the 50x40 frame"):
        points_mask((40, 50), [(50.0, 3.0)], sigma=3)
