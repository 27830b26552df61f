"""Tests for egonet.dhg: gravity and height from depth, and the DHG codec.

The scenes are rendered analytically here: a room (floor, walls, ceiling)
with a table and a cabinet, seen by a pinhole camera at a known height, pitch
and roll, so the true gravity and the true height of every pixel are known.
"""

import numpy as np
import pytest

from egonet import dhg

ROOM = ((-3.0, 3.0), (-2.0, 5.0), (0.0, 2.8))  # x (right), y (ahead), z (up) in metres
TABLE = ((-0.6, 0.6), (1.2, 2.0), (0.0, 0.75))
CABINET = ((1.8, 3.0), (2.0, 3.0), (0.0, 0.9))


def camera_axes(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """Camera axes (columns x right, y down, z forward) in world coordinates (z up)."""
    p, r = np.radians(pitch_deg), np.radians(roll_deg)
    x = np.array([1.0, 0.0, 0.0])
    y = np.array([0.0, -np.sin(p), -np.cos(p)])
    z = np.array([0.0, np.cos(p), -np.sin(p)])
    return np.stack([np.cos(r) * x + np.sin(r) * y, -np.sin(r) * x + np.cos(r) * y, z], axis=1)


def render(
    *,
    pitch: float,
    roll: float = 0.0,
    cam_h: float = 1.5,
    size: tuple[int, int] = (240, 320),
    f: float = 262.5,
    principal: tuple[float, float] | None = None,
    room=ROOM,
    boxes=(TABLE, CABINET),
):
    """Render z-depth, K, true height per pixel and true up (camera coordinates)."""
    h, w = size
    cx, cy = principal if principal is not None else ((w - 1) / 2, (h - 1) / 2)
    K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = np.stack([(u - cx) / f, (v - cy) / f, np.ones((h, w))], axis=-1)
    axes = camera_axes(pitch, roll)
    d = rays @ axes.T  # ray directions in the world; z-depth is the ray parameter
    c = np.array([0.0, 0.0, cam_h])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.full((h, w), np.inf)
        for ax, (lo, hi) in enumerate(room):  # leave the room through its nearest face
            da = d[..., ax]
            t = np.minimum(t, np.where(da > 0, (hi - c[ax]) / da, np.where(da < 0, (lo - c[ax]) / da, np.inf)))
        for box in boxes:  # slab test
            near = np.full((h, w), -np.inf)
            far = np.full((h, w), np.inf)
            for ax, (lo, hi) in enumerate(box):
                da = d[..., ax]
                t1, t2 = (lo - c[ax]) / da, (hi - c[ax]) / da
                inside = lo <= c[ax] <= hi
                t1 = np.where(da == 0, -np.inf if inside else np.inf, t1)
                t2 = np.where(da == 0, np.inf if inside else -np.inf, t2)
                near = np.maximum(near, np.minimum(t1, t2))
                far = np.minimum(far, np.maximum(t1, t2))
            hit = (near <= far) & (near > 0) & (near < t)
            t = np.where(hit, near, t)
    height = cam_h + t * d[..., 2]
    up = axes.T @ np.array([0.0, 0.0, 1.0])
    return t, K, height, up


def corrupt(depth: np.ndarray, seed: int, *, noise: float = 0.01, holes: int = 12):
    """1 % multiplicative noise and random missing blocks (half NaN, half 0)."""
    rng = np.random.default_rng(seed)
    noisy = depth * (1 + noise * rng.standard_normal(depth.shape))
    h, w = depth.shape
    missing = np.zeros(depth.shape, bool)
    for _ in range(holes):
        bh, bw = rng.integers(h // 20, h // 6), rng.integers(w // 20, w // 6)
        y0, x0 = rng.integers(0, h - bh), rng.integers(0, w - bw)
        missing[y0 : y0 + bh, x0 : x0 + bw] = True
    noisy[missing] = np.nan
    noisy[missing & (rng.random(depth.shape) < 0.5)] = 0.0
    return noisy.astype(np.float32), missing


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


# --- gravity and height ---------------------------------------------------------


@pytest.mark.parametrize(
    ("pitch", "roll", "cam_h"),
    [(0, 0, 1.5), (20, 0, 1.6), (45, 0, 1.5), (55, 0, 1.2), (55, 12, 1.7), (30, -15, 1.4), (45, 20, 1.3)],
)
def test_gravity_and_height_on_noisy_scene_with_holes(pitch, roll, cam_h):
    depth, K, true_h, true_up = render(pitch=pitch, roll=roll, cam_h=cam_h)
    noisy, missing = corrupt(depth, seed=pitch * 100 + roll)

    est = dhg.estimate_height(noisy, K)

    assert angle_deg(est.up, true_up) < 2.0
    assert est.floor_visible
    assert est.camera_height_m == pytest.approx(cam_h, abs=0.03)
    assert est.height_m.dtype == np.float32 and est.height_m.shape == depth.shape
    assert np.array_equal(np.isnan(est.height_m), missing)
    ok = ~missing
    assert np.median(np.abs(est.height_m[ok] - true_h[ok])) < 0.03
    floor = ok & (np.abs(true_h) < 1e-6)
    table = ok & (np.abs(true_h - TABLE[2][1]) < 1e-6)
    assert floor.sum() > 1000
    assert abs(np.median(est.height_m[floor])) < 0.03
    if table.sum() > 200:  # the table is out of view at some pitches
        assert np.median(est.height_m[table]) == pytest.approx(TABLE[2][1], abs=0.03)
    assert est.pitch_deg == pytest.approx(pitch, abs=2.0)
    assert est.roll_deg == pytest.approx(roll, abs=2.0)


def test_height_map_returns_height_and_unit_up():
    depth, K, true_h, true_up = render(pitch=45)
    height, up = dhg.height_map(depth, K)
    assert height.dtype == np.float32 and height.shape == depth.shape
    assert up.shape == (3,) and np.linalg.norm(up) == pytest.approx(1.0)
    assert angle_deg(up, true_up) < 0.5
    assert np.nanmax(np.abs(height - true_h)) < 0.02  # noise-free: every pixel


def test_steep_pitch_is_not_read_as_looking_up_at_the_wall():
    # Looking 55 degrees down with the wall ahead in view: the classic start
    # from the camera's -y axis converges to "looking up at a ceiling".
    depth, K, _, true_up = render(pitch=55, cam_h=1.5, room=((-3.0, 3.0), (-2.0, 2.5), (0.0, 2.8)))
    classic = dhg._iterate_gravity(_normals(depth, K), dhg.LEVEL_UP[None, :], dhg._PASSES)[0]
    assert angle_deg(classic, true_up) > 30  # the failure this module works around
    _, up = dhg.height_map(depth, K)
    assert angle_deg(up, true_up) < 1.0


def _normals(depth, K):
    valid = np.isfinite(depth) & (depth > 0)
    x, y = dhg.normalised_coords(K, depth.shape)
    normals, _, _ = dhg._plane_normals(depth.astype(np.float64), valid, x, y)
    return normals


def test_off_centre_principal_point_and_larger_image():
    depth, K, true_h, true_up = render(pitch=35, roll=-8, size=(480, 640), f=525.0, principal=(300.0, 260.0))
    noisy, missing = corrupt(depth, seed=7)
    height, up = dhg.height_map(noisy, K)
    assert angle_deg(up, true_up) < 2.0
    assert np.median(np.abs(height[~missing] - true_h[~missing])) < 0.03


def test_floor_out_of_view_assumes_camera_1_3_m_above_floor():
    # Looking 10 degrees up: walls and ceiling only.
    depth, K, true_h, true_up = render(pitch=-10, cam_h=1.6)
    est = dhg.estimate_height(depth, K)
    assert not est.floor_visible and est.floor_fraction == 0.0
    assert angle_deg(est.up, true_up) < 1.0
    assert est.camera_height_m == pytest.approx(dhg.ASSUMED_CAMERA_HEIGHT_M)
    # Heights are right up to the 0.3 m offset of the wrong camera height.
    assert np.nanmedian(np.abs(est.height_m - (true_h - 0.3))) < 0.01
    custom = dhg.estimate_height(depth, K, assumed_camera_height_m=1.6)
    assert np.nanmedian(np.abs(custom.height_m - true_h)) < 0.01


def test_counter_top_close_below_camera_is_not_the_floor():
    counter = ((-3.0, 3.0), (-2.0, 5.0), (0.0, 1.0))  # fills the view, 0.2 m below the camera
    depth, K, true_h, true_up = render(pitch=60, cam_h=1.2, boxes=(counter,))
    est = dhg.estimate_height(depth, K)
    assert angle_deg(est.up, true_up) < 1.0
    assert not est.floor_visible
    assert est.camera_height_m == pytest.approx(1.3)
    assert np.nanmedian(est.height_m) == pytest.approx(1.1, abs=0.02)


def test_no_planar_surface_falls_back_to_level_camera():
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 4.0, (60, 80))  # no plane anywhere
    K = np.array([[70.0, 0, 40], [0, 70.0, 30], [0, 0, 1]])
    est = dhg.estimate_height(depth, K)
    assert est.n_normals < 50
    np.testing.assert_array_equal(est.up, dhg.LEVEL_UP)
    assert not est.floor_visible
    assert np.isfinite(est.height_m).all()


def test_missing_values_nan_zero_negative_inf_all_count_as_missing():
    depth, K, _, _ = render(pitch=30)
    depth = depth.copy()
    depth[10:20, 10:20] = np.nan
    depth[30:40, 30:40] = 0.0
    depth[50:60, 50:60] = -1.0
    depth[70:80, 70:80] = np.inf
    height, _ = dhg.height_map(depth, K)
    bad = np.zeros(depth.shape, bool)
    for s in (slice(10, 20), slice(30, 40), slice(50, 60), slice(70, 80)):
        bad[s, s] = True
    np.testing.assert_array_equal(np.isnan(height), bad)


@pytest.mark.parametrize(
    ("depth", "K", "match"),
    [
        (np.ones((4, 20, 20)), np.eye(3), "2-D map"),
        (np.ones((5, 20)), np.eye(3), "at least 8x8"),
        (np.ones((20, 20), np.uint16), np.eye(3), "millimetres"),
        (np.full((20, 20), 1861.0), np.eye(3), "millimetres"),
        (np.zeros((20, 20)), np.eye(3), "no valid pixel"),
        (np.full((20, 20), np.nan), np.eye(3), "no valid pixel"),
        (np.ones((20, 20)), np.eye(2), "3x3 camera matrix"),
        (np.ones((20, 20)), [1, 0, 0, 0, 1, 0, 10, 10, 1], "column-major"),
        (np.ones((20, 20)), np.array([[100.0, 0, 0], [0, 100, 0], [10, 10, 1]]), "last row"),
        (np.ones((20, 20)), np.diag([-100.0, 100.0, 1.0]), "focal lengths"),
        (np.ones((20, 20)), np.full((3, 3), np.nan), "finite"),
        (np.ones((20, 20)), "K", "3x3 camera matrix"),
    ],
)
def test_height_map_rejects_bad_input(depth, K, match):
    with pytest.raises(ValueError, match=match):
        dhg.height_map(depth, K)


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("assumed_camera_height_m", 0.0),
        ("min_camera_height_m", -1.0),
        ("min_floor_fraction", 1.5),
        ("min_floor_fraction", True),
    ],
)
def test_estimate_height_rejects_bad_options(option, value):
    depth, K, _, _ = render(pitch=30)
    with pytest.raises(ValueError, match=option):
        dhg.estimate_height(depth, K, **{option: value})


# --- DHG codec ------------------------------------------------------------------


def test_encode_hand_checked_codes():
    depth = np.array([[0.0, 0.03, 3.0, 7.62, 20.0, np.nan]])
    height = np.array([[0.5, 0.0, -0.2, 2.34, 5.0, 0.0]])
    gray = np.array([[0, 1, 2, 3, 4, 255]], np.uint8)
    out = dhg.encode_dhg(depth, height, gray)
    assert out.dtype == np.uint8 and out.shape == (1, 6, 3)
    # The authors' file order: gray, height, depth.
    assert (dhg.GRAY, dhg.HEIGHT, dhg.DEPTH) == (0, 1, 2)
    assert out[0, :, 0].tolist() == gray[0].tolist()
    assert out[0, :, 1].tolist() == [0, 21, 1, 255, 255, 0]  # missing depth -> missing height
    assert out[0, :, 2].tolist() == [0, 2, 101, 255, 255, 0]  # depth 0 is missing; 20 m clips


def test_decode_by_name_reads_depth_from_the_last_channel():
    image = np.zeros((1, 2, 3), np.uint8)
    image[0, :, 0] = [7, 9]  # gray
    image[0, :, 1] = [21, 121]  # height: the floor, then 1 m
    image[0, :, 2] = [134, 0]  # depth: 4 m (3.99 after quantisation), then missing
    decoded = dhg.decode_dhg(image)
    assert decoded.gray.tolist() == [[7, 9]]
    np.testing.assert_allclose(decoded.height, [[0.0, 1.0]], atol=1e-6)
    assert decoded.depth[0, 0] == pytest.approx(4.0, abs=0.015) and np.isnan(decoded.depth[0, 1])
    depth, height, gray = decoded  # unpacks in the same order as the names
    assert depth is decoded.depth and height is decoded.height and gray is decoded.gray


def test_encode_decode_round_trip_within_quantisation():
    rng = np.random.default_rng(1)
    depth = rng.uniform(0.05, dhg.DEPTH_MAX_M, (40, 50)).astype(np.float32)
    height = rng.uniform(dhg.HEIGHT_MIN_M, dhg.HEIGHT_MAX_M, (40, 50)).astype(np.float32)
    gray = rng.integers(0, 256, (40, 50), dtype=np.uint8)
    depth[:5] = np.nan
    depth[5:8] = 0.0
    height[10:12] = np.nan
    d, h, g = dhg.decode_dhg(dhg.encode_dhg(depth, height, gray))
    assert d.dtype == h.dtype == np.float32
    np.testing.assert_array_equal(g, gray)
    missing_d = ~(depth > 0)
    np.testing.assert_array_equal(np.isnan(d), missing_d)
    np.testing.assert_array_equal(np.isnan(h), missing_d | np.isnan(height))
    depth_step = dhg.DEPTH_MAX_M / 254
    height_step = (dhg.HEIGHT_MAX_M - dhg.HEIGHT_MIN_M) / 254
    assert np.nanmax(np.abs(d - depth)) <= depth_step / 2 + 1e-6
    assert np.nanmax(np.abs(h - height)) <= height_step / 2 + 1e-6


def test_decode_clipped_values_come_back_at_range_ends():
    out = dhg.encode_dhg(np.array([[20.0, 1.0]]), np.array([[-3.0, 9.0]]), np.zeros((1, 2), np.uint8))
    d, h, _ = dhg.decode_dhg(out)
    np.testing.assert_allclose(d, [[dhg.DEPTH_MAX_M, 1.0]], atol=0.015)
    np.testing.assert_allclose(h, [[dhg.HEIGHT_MIN_M, dhg.HEIGHT_MAX_M]], atol=1e-6)


@pytest.mark.parametrize(
    ("depth", "height", "gray", "match"),
    [
        (np.ones((4, 4)), np.ones((4, 5)), np.zeros((4, 4), np.uint8), "height_m has shape"),
        (np.ones((4, 4)), np.ones((4, 4)), np.zeros((4, 4, 3), np.uint8), "gray must be a"),
        (np.ones((4, 4)), np.ones((4, 4)), np.zeros((4, 4), np.float32), "gray must be uint8"),
        (np.ones(4), np.ones(4), np.zeros(4, np.uint8), "depth_m must be a 2-D"),
        (np.ones((4, 4), np.uint16), np.ones((4, 4)), np.zeros((4, 4), np.uint8), "millimetres"),
    ],
)
def test_encode_rejects_bad_input(depth, height, gray, match):
    with pytest.raises(ValueError, match=match):
        dhg.encode_dhg(depth, height, gray)


@pytest.mark.parametrize(
    ("image", "match"),
    [
        (np.zeros((4, 4), np.uint8), r"\(H, W, 3\)"),
        (np.zeros((4, 4, 4), np.uint8), r"\(H, W, 3\)"),
        (np.zeros((4, 4, 3)), "uint8"),
    ],
)
def test_decode_rejects_bad_input(image, match):
    with pytest.raises(ValueError, match=match):
        dhg.decode_dhg(image)


# --- convenience ---------------------------------------------------------------


def test_dhg_from_depth_floor_dark_and_brighter_with_height():
    depth, K, true_h, _ = render(pitch=40, cam_h=1.5)
    rgb = np.zeros(depth.shape + (3,), np.uint8)
    rgb[..., 0] = 200  # pure red: gray is 0.299 * 200 = 60
    out = dhg.dhg_from_depth(depth, K, rgb)
    assert out.shape == depth.shape + (3,) and out.dtype == np.uint8
    assert np.all(out[..., dhg.GRAY] == 60)
    np.testing.assert_allclose(dhg.decode_dhg(out).depth, np.where(depth > 0, depth, np.nan), atol=0.016)
    floor = np.abs(true_h) < 1e-6
    table = np.abs(true_h - TABLE[2][1]) < 1e-6
    assert abs(np.median(out[..., 1][floor].astype(int)) - 21) <= 1  # height 0 m is code 21
    assert np.median(out[..., 1][table]) == pytest.approx(21 + 75, abs=2)  # 1 cm a code
    _, h, _ = dhg.decode_dhg(out)
    assert np.median(np.abs(h - true_h)) < 0.02


def test_dhg_from_depth_rejects_mismatched_rgb():
    depth, K, _, _ = render(pitch=40)
    with pytest.raises(ValueError, match="rgb must be a"):
        dhg.dhg_from_depth(depth, K, np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(ValueError, match="rgb must be uint8"):
        dhg.dhg_from_depth(depth, K, np.zeros(depth.shape + (3,)))
