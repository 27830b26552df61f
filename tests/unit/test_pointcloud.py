"""Tests for egonet.pointcloud: depth + intrinsics -> points, the PLY file, the browser's encoding."""

import struct

import numpy as np
import pytest

from egonet.pointcloud import MARK_COLORS, encode_points, frame_cloud, marked_colors, write_ply

K = np.array([[2.0, 0.0, 1.0], [0.0, 4.0, 0.5], [0.0, 0.0, 1.0]])


def small():
    depth = np.array([[2.0, 0.0, 1.0], [4.0, 1.0, np.nan]], np.float32)  # two missing
    rgb = np.arange(18, dtype=np.uint8).reshape(2, 3, 3) * 10
    return depth, rgb


def test_back_projection_by_hand():
    depth, rgb = small()
    cloud = frame_cloud(depth, K, rgb)
    assert cloud.stride == 1 and len(cloud) == 4
    np.testing.assert_array_equal(cloud.pixels, [[0, 0], [0, 2], [1, 0], [1, 1]])
    # X = (col - 1) Z / 2, Y = (row - 0.5) Z / 4
    np.testing.assert_allclose(cloud.xyz, [[-1.0, -0.25, 2.0], [0.5, -0.125, 1.0], [-2.0, 0.5, 4.0], [0.0, 0.125, 1.0]])
    np.testing.assert_array_equal(cloud.rgb[1], rgb[0, 2])
    assert not cloud.truth.any() and not cloud.predicted.any()


def test_truth_and_prediction_flags_and_marked_colours():
    depth, rgb = small()
    truth = np.array([[True, True, False], [False, False, False]])
    probability = np.array([[0.9, 0.1, 0.6], [0.2, 0.5, 0.9]], np.float32)
    cloud = frame_cloud(depth, K, rgb, truth=truth, probability=probability, threshold=0.5)
    assert cloud.truth.tolist() == [True, False, False, False]
    assert cloud.predicted.tolist() == [True, True, False, True]  # >= 0.5
    colors = marked_colors(cloud)
    # both -> yellow blend, predicted only -> red blend, unmarked unchanged
    np.testing.assert_array_equal(colors[0], np.round(0.35 * rgb[0, 0] + 0.65 * np.array(MARK_COLORS["both"])))
    np.testing.assert_array_equal(colors[1], np.round(0.35 * rgb[0, 2] + 0.65 * np.array(MARK_COLORS["predicted"])))
    np.testing.assert_array_equal(colors[2], rgb[1, 0])


def test_subsampling_keeps_an_even_grid_under_the_bound():
    depth = np.ones((100, 120), np.float32)
    depth[:, :10] = 0
    rgb = np.zeros((100, 120, 3), np.uint8)
    cloud = frame_cloud(depth, np.eye(3) * [[50], [50], [1]], rgb, max_points=1000)
    assert len(cloud) <= 1000 and cloud.stride == 4  # 110 x 100 valid pixels: stride 3 keeps 1,258
    assert set(np.unique(cloud.pixels[:, 0] % 4)) == {0} and set(np.unique(cloud.pixels[:, 1] % 4)) == {0}
    assert len(frame_cloud(np.zeros((5, 5), np.float32), K, np.zeros((5, 5, 3), np.uint8))) == 0


def test_bad_inputs_are_named():
    depth, rgb = small()
    with pytest.raises(ValueError, match="K must be a finite"):
        frame_cloud(depth, np.eye(2), rgb)
    with pytest.raises(ValueError, match=r"depth_m must be a float array of shape \(2, 3\)"):
        frame_cloud(np.nan_to_num(depth * 1000).astype(np.uint16), K, rgb)
    with pytest.raises(ValueError, match="truth must be a bool array"):
        frame_cloud(depth, K, rgb, truth=np.zeros((3, 3), bool))
    with pytest.raises(ValueError, match="max_points"):
        frame_cloud(depth, K, rgb, max_points=0)


def test_ply_round_trip(tmp_path):
    from plyfile import PlyData

    depth, rgb = small()
    truth = np.array([[True, False, False], [False, True, False]])
    cloud = frame_cloud(depth, K, rgb, truth=truth)
    write_ply(tmp_path / "frame.ply", cloud, comments=("frame 7",))
    ply = PlyData.read(str(tmp_path / "frame.ply"))
    vertex = ply["vertex"]
    assert vertex.count == 4 and "frame 7" in ply.comments and not ply.text
    np.testing.assert_allclose(np.stack([vertex["x"], vertex["y"], vertex["z"]], 1), cloud.xyz)
    assert vertex["truth"].tolist() == [1, 0, 0, 1] and vertex["predicted"].tolist() == [0, 0, 0, 0]
    np.testing.assert_array_equal(np.stack([vertex["red"], vertex["green"], vertex["blue"]], 1), marked_colors(cloud))


def test_browser_encoding_layout():
    depth, rgb = small()
    cloud = frame_cloud(depth, K, rgb, truth=np.ones((2, 3), bool), probability=np.zeros((2, 3), np.float32) + 0.7)
    data = encode_points(cloud)
    assert data[:4] == b"EGP1" and struct.unpack("<I", data[4:8]) == (4,)
    xyz = np.frombuffer(data, "<f4", count=12, offset=8).reshape(4, 3)
    rgba = np.frombuffer(data, np.uint8, offset=8 + 48).reshape(4, 4)
    np.testing.assert_array_equal(xyz, cloud.xyz)
    np.testing.assert_array_equal(rgba[:, :3], cloud.rgb)
    assert rgba[:, 3].tolist() == [3, 3, 3, 3]  # labelled and predicted
    assert len(data) == 8 + 4 * 16


def test_real_rgbd_frame_puts_the_chair_before_the_wall():
    from egonet import io
    from tests.realdata import PRIMESENSE, chair_truth

    if not PRIMESENSE.exists():
        pytest.skip("the shared real frames are absent")
    depth = io.read_depth(PRIMESENSE / "depth" / "00001.png")
    K_real = io.read_intrinsics(PRIMESENSE / "camera_primesense.json")
    cloud = frame_cloud(depth, K_real, io.read_image(PRIMESENSE / "color" / "00001.jpg"), truth=chair_truth(), max_points=40_000)
    assert 20_000 < len(cloud) <= 40_000 and cloud.stride == 3
    chair, rest = cloud.xyz[cloud.truth], cloud.xyz[~cloud.truth]
    assert len(chair) > 1000
    # Measured: the chair's median depth 1.73 m, the rest (wall, floor) 1.92 m.
    assert 1.4 < np.median(chair[:, 2]) < np.median(rest[:, 2]) < 2.5
    # The chair is right of the image centre (its box spans columns 335-610 of 640): x > 0.
    assert np.median(chair[:, 0]) > 0
