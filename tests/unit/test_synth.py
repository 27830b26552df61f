"""Tests for egonet.synth: determinism, geometry, ground truth and validation."""

import json
import math
from statistics import mean

import numpy as np
import pytest

from egonet.synth import (
    ACTIVITIES,
    ARM_REACH_M,
    HFOV_DEG,
    VISUAL_RANGE_M,
    SynthFrame,
    intrinsics,
    render_activity,
    render_frame,
)

W, H = 128, 96
PER_ACTIVITY = 6


@pytest.fixture(scope="module")
def frames() -> dict[str, list[SynthFrame]]:
    """A few small frames of every activity, rendered once for the module."""
    return {a: [render_frame(a, i, seed=0, width=W, height=H) for i in range(PER_ACTIVITY)] for a in ACTIVITIES}


def all_frames(frames):
    return [f for fs in frames.values() for f in fs]


def assert_same_frame(a: SynthFrame, b: SynthFrame) -> None:
    for name in ("rgb", "depth_m", "height_m", "mask", "K"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.meta == b.meta


# --------------------------------------------------------------------------
# Determinism


def test_same_arguments_give_identical_frames():
    a = render_frame("cooking", 3, seed=5, width=96, height=72)
    b = render_frame("cooking", 3, seed=5, width=96, height=72)
    assert_same_frame(a, b)


def test_seed_and_index_change_the_frame():
    base = render_frame("dining", 2, seed=0, width=96, height=72)
    other_seed = render_frame("dining", 2, seed=1, width=96, height=72)
    other_index = render_frame("dining", 3, seed=0, width=96, height=72)
    assert not np.array_equal(base.depth_m, other_seed.depth_m)
    assert not np.array_equal(base.depth_m, other_index.depth_m)
    assert not np.array_equal(base.rgb, other_seed.rgb)


def test_render_activity_equals_render_frame():
    frames = list(render_activity("hotel", 3, seed=2, width=64, height=48))
    assert [f.index for f in frames] == [0, 1, 2]
    for f in frames:
        assert_same_frame(f, render_frame("hotel", f.index, seed=2, width=64, height=48))
    assert list(render_activity("hotel", 0)) == []


def test_scene_does_not_depend_on_resolution():
    small = render_frame("grocery", 4, width=64, height=48)
    large = render_frame("grocery", 4, width=192, height=144)
    for key in ("kind", "object", "object_distance_m", "camera_height_m", "pitch_deg", "roll_deg"):
        assert small.meta[key] == large.meta[key], key
    # The same mask, sampled three times more finely.
    assert abs(small.mask.mean() - large.mask.mean()) < 0.01


# --------------------------------------------------------------------------
# Shapes, dtypes, metadata, intrinsics


def test_shapes_dtypes_and_meta(frames):
    f = frames["desk work"][0]
    assert f.activity == "desk work" and f.index == 0
    assert f.rgb.shape == (H, W, 3) and f.rgb.dtype == np.uint8
    assert f.depth_m.shape == (H, W) and f.depth_m.dtype == np.float32
    assert f.height_m.shape == (H, W) and f.height_m.dtype == np.float32
    assert f.mask.shape == (H, W) and f.mask.dtype == np.bool_
    assert f.K.shape == (3, 3) and f.K.dtype == np.float64
    meta = json.loads(json.dumps(f.meta))  # plain JSON types only
    for key in ("camera_height_m", "pitch_deg", "roll_deg", "kind", "object", "object_distance_m", "up_cam"):
        assert key in meta
    assert meta["kind"] in ("tactile", "visual")
    assert 0.0 <= meta["pitch_deg"] <= 60.0


def test_rgb_has_texture_and_colour(frames):
    for f in all_frames(frames):
        assert f.rgb.std() > 10.0
        packed = f.rgb.astype(np.int32) @ np.array([1 << 16, 1 << 8, 1], dtype=np.int32)
        assert len(np.unique(packed)) > 500


def test_intrinsics_centre_and_field_of_view():
    K = intrinsics(width=320, height=240)
    assert K[0, 2] == pytest.approx(159.5) and K[1, 2] == pytest.approx(119.5)
    assert K[0, 0] == K[1, 1]
    assert math.degrees(2 * math.atan(160 / K[0, 0])) == pytest.approx(HFOV_DEG)
    K2 = intrinsics(width=1280, height=960)
    assert K2[0, 0] == pytest.approx(4 * K[0, 0])
    np.testing.assert_array_equal(render_frame("hotel", 0, width=80, height=60).K, intrinsics(width=80, height=60))


# --------------------------------------------------------------------------
# Masks and ground truth


def test_every_frame_has_a_reasonable_mask(frames):
    for activity, fs in frames.items():
        for f in fs:
            assert f.mask.any(), (activity, f.index)
            assert f.mask.mean() >= 0.004, (activity, f.index, f.mask.mean())
            assert np.all(f.depth_m[f.mask] > 0)


def test_mask_depth_matches_the_rule(frames):
    for f in all_frames(frames):
        median = float(np.median(f.depth_m[f.mask]))
        if f.meta["kind"] == "tactile":
            assert median <= ARM_REACH_M + 0.05, (f.activity, f.index, median)
            assert f.meta["object_distance_m"] <= ARM_REACH_M
            assert f.meta["hands_touching"], (f.activity, f.index)
        else:
            assert median <= VISUAL_RANGE_M + 0.3, (f.activity, f.index, median)
            assert f.meta["object_distance_m"] <= VISUAL_RANGE_M
            assert f.meta["hands_touching"] == []


def test_visual_objects_lie_on_the_gaze_ray(frames):
    visual = [f for f in all_frames(frames) if f.meta["kind"] == "visual"]
    assert visual
    for f in visual:
        v, u = np.nonzero(f.mask)
        assert abs(u.mean() - f.K[0, 2]) < 0.2 * W, (f.activity, f.index)
        assert abs(v.mean() - f.K[1, 2]) < 0.2 * H, (f.activity, f.index)


def test_tactile_and_visual_are_mixed(frames):
    kinds = [f.meta["kind"] for f in all_frames(frames)]
    tactile = kinds.count("tactile") / len(kinds)
    assert 0.45 <= tactile <= 0.9
    many = [render_frame("hotel", i, width=48, height=36).meta["kind"] for i in range(12)]
    assert "visual" in many and "tactile" in many


def test_same_kind_distractors_are_present(frames):
    counts = [f.meta["same_kind_distractors"] for f in all_frames(frames)]
    assert sum(c > 0 for c in counts) >= 0.7 * len(counts)
    assert min(f.meta["n_objects"] for f in all_frames(frames)) >= 3


def test_hands_appear_in_tactile_frames(frames):
    tactile = [f for f in all_frames(frames) if f.meta["kind"] == "tactile"]
    assert tactile
    assert mean(f.meta["hands_visible"] for f in tactile) > 0.9


# --------------------------------------------------------------------------
# Geometry: depth and height


def up_in_camera(meta):
    p = math.radians(meta["pitch_deg"])
    r = math.radians(meta["roll_deg"])
    return np.array([-math.sin(r) * math.cos(p), -math.cos(r) * math.cos(p), -math.sin(p)])


def test_height_matches_back_projected_depth(frames):
    for f in all_frames(frames):
        v, u = np.mgrid[0:H, 0:W]
        rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(f.K).T
        points = rays * f.depth_m[..., None]
        expected = f.meta["camera_height_m"] + points @ up_in_camera(f.meta)
        valid = f.depth_m > 0
        assert valid.mean() > 0.99  # the rooms are closed
        np.testing.assert_allclose(f.height_m[valid], expected[valid], atol=2e-3)
        assert np.all(np.isnan(f.height_m[~valid]))
        np.testing.assert_allclose(f.meta["up_cam"], up_in_camera(f.meta), atol=1e-5)


def test_floor_is_at_zero_and_nothing_is_below_it(frames):
    floor_seen = 0
    for f in all_frames(frames):
        h = f.height_m[f.depth_m > 0]
        assert h.min() > -2e-3
        assert h.max() < 3.6
        if np.mean(np.abs(h) < 5e-3) > 0.02:
            floor_seen += 1
    assert floor_seen >= 10


def test_mask_height_is_that_of_the_object(frames):
    for f in all_frames(frames):
        h = float(np.median(f.height_m[f.mask]))
        assert abs(h - f.meta["object_height_m"]) < 0.35, (f.activity, f.index)


# --------------------------------------------------------------------------
# Activities differ


def test_activities_differ_in_layout(frames):
    cam = {a: mean(f.meta["camera_height_m"] for f in fs) for a, fs in frames.items()}
    assert max(cam["dining"], cam["desk work"]) < 1.4 < min(cam["cooking"], cam["grocery"], cam["dishwashing"])
    objects = {a: {f.meta["object"] for f in fs} for a, fs in frames.items()}
    assert not objects["grocery"] & objects["desk work"]
    assert not objects["shopping"] & objects["cooking"]
    pitch = {a: mean(f.meta["pitch_deg"] for f in fs) for a, fs in frames.items()}
    assert pitch["dishwashing"] > pitch["grocery"]


# --------------------------------------------------------------------------
# Bad arguments


def test_unknown_activity_lists_the_valid_names():
    with pytest.raises(ValueError, match="activity") as info:
        render_frame("gardening", 0)
    for name in ACTIVITIES:
        assert repr(name) in str(info.value)
    with pytest.raises(ValueError, match="activity"):
        render_activity("Cooking", 2)
    with pytest.raises(ValueError, match="activity"):
        render_frame(3, 0)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"width": 0}, "width"),
        ({"width": -5}, "width"),
        ({"width": 32.0}, "width"),
        ({"height": 0}, "height"),
        ({"seed": -1}, "seed"),
        ({"seed": True}, "seed"),
        ({"seed": 2**32}, "seed"),
    ],
)
def test_bad_sizes_and_seeds(kwargs, name):
    with pytest.raises(ValueError, match=name):
        render_frame("cooking", 0, **kwargs)
    with pytest.raises(ValueError, match=name):
        render_activity("cooking", 1, **kwargs)


def test_bad_index_and_count():
    with pytest.raises(ValueError, match="index"):
        render_frame("cooking", -1)
    with pytest.raises(ValueError, match="count"):
        render_activity("cooking", -1)  # raised at the call, before iterating
    with pytest.raises(ValueError, match="count"):
        render_activity("cooking", 2.5)
    with pytest.raises(ValueError, match="width"):
        intrinsics(width=0, height=10)


# --------------------------------------------------------------------------
# Full resolution


@pytest.mark.slow
def test_native_resolution_frame():
    f = render_frame("shopping", 1, width=1280, height=960)
    assert f.rgb.shape == (960, 1280, 3)
    assert f.mask.mean() >= 0.005
    small = render_frame("shopping", 1, width=160, height=120)
    assert f.meta["object"] == small.meta["object"]
