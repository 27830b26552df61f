"""Proposals without a trained model (egonet.proposals): depth finds the handled object, each source
answers a map, and bad input is refused in words."""

import cv2
import numpy as np
import pytest

from egonet import io, proposals, synth
from egonet.errors import EgonetError
from tests.realdata import PRIMESENSE, chair_truth


def best_region_iou(probability: np.ndarray, truth: np.ndarray) -> float:
    """IoU with the truth of the region of the map at or above the threshold that overlaps it most."""
    n, labels = cv2.connectedComponents((probability >= proposals.THRESHOLD).astype(np.uint8))
    return max((float(((labels == k) & truth).sum() / ((labels == k) | truth).sum()) for k in range(1, n)), default=0.0)


def test_depth_finds_the_bag_a_hand_holds_in_a_demo_frame():
    frame = synth.render_frame("shopping", 1, seed=0, width=320, height=240)
    assert frame.meta["kind"] == "tactile" and frame.meta["object"] == "handbag"
    probability = proposals.source_map("depth", frame.rgb, frame.depth_m, frame.K)
    assert probability.shape == (240, 320) and probability.dtype == np.float32 and probability.max() == 1.0
    assert best_region_iou(probability, frame.mask) > 0.8  # measured 0.90 (before GrabCut)


def test_depth_proposes_the_box_before_the_wall_not_the_table_it_stands_on():
    K = np.array([[100.0, 0, 80], [0, 100.0, 60], [0, 0, 1]])
    v = np.arange(120.0)[:, None].repeat(160, axis=1)
    depth = np.minimum(np.where(v > 60, 0.6 * 100 / np.maximum(v - 60, 1), 2.5), 2.5).astype(np.float32)
    depth[75:95, 65:95] = 0.9  # a box 0.9 m ahead, over a table top 0.6 m below the camera, a wall at 2.5 m
    rgb = np.random.default_rng(0).integers(100, 140, (120, 160, 3), dtype=np.uint8)
    probability = proposals.depth_objects(rgb, depth, K)
    box = np.zeros((120, 160), bool)
    box[75:95, 65:95] = True
    assert best_region_iou(probability, box) > 0.8  # 600 of 700 px: the rim that gave way joins it
    assert probability[110, 10] == 0 and probability[110, 150] == 0  # the table top is a support


@pytest.mark.skipif(not PRIMESENSE.exists(), reason="shared data not present")
def test_depth_proposes_the_chair_of_the_real_rgbd_frames():
    K = io.read_intrinsics(PRIMESENSE / "camera_primesense.json")
    ious = []
    for name in ("00000", "00001", "00002"):
        rgb = io.read_image(PRIMESENSE / "color" / f"{name}.jpg")
        depth = io.read_depth(PRIMESENSE / "depth" / f"{name}.png")
        ious.append(best_region_iou(proposals.source_map("depth", rgb, depth, K), chair_truth()))
    # Measured 0.44, 0.83, 0.67 before GrabCut: seat and arms always, the back (further, higher) with
    # them on 00001 and 00002 only, the wall seen through the right arm's loop in them.
    assert min(ious) > 0.35 and np.mean(ious) > 0.55, ious


def test_every_source_answers_a_map_of_the_frame():
    frame = synth.render_frame("hotel", 1, seed=0, width=160, height=120)
    for source in proposals.SOURCES:
        probability = proposals.source_map(source, frame.rgb, frame.depth_m, frame.K)
        assert probability.shape == (120, 160) and 0.0 <= probability.min() <= probability.max() <= 1.0, source
    # Without intrinsics the depth source assumes a field of view rather than refusing.
    assert proposals.source_map("depth", frame.rgb, frame.depth_m).shape == (120, 160)


def test_bad_input_is_refused_in_words():
    rgb = np.zeros((48, 64, 3), np.uint8)
    with pytest.raises(EgonetError, match="unknown source 'model'; valid sources: depth, handled, saliency"):
        proposals.source_map("model", rgb)
    with pytest.raises(EgonetError, match="needs the frame's depth; this frame has none") as caught:
        proposals.source_map("depth", rgb, None)
    assert caught.value.field == "source"
    with pytest.raises(EgonetError, match=r"depth_m must be float metres of the frame's size \(48, 64\)"):
        proposals.depth_objects(rgb, np.ones((48, 64), np.uint16))
    with pytest.raises(EgonetError, match="no valid pixel"):
        proposals.depth_objects(rgb, np.zeros((48, 64), np.float32))
