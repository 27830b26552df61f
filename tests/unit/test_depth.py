"""Depth for RGB-only frames: the scale-invariant loss, the errors, assumed intrinsics, the network, training, prediction."""

import math

import numpy as np
import pytest
import torch

from egonet.checkpoint import load_checkpoint
from egonet.depth import (
    DEPTH_MODEL,
    DepthConfig,
    DepthErrors,
    DepthPredictor,
    DepthSample,
    assumed_intrinsics,
    depth_errors,
    fit_depth,
    scale_invariant_loss,
)
from egonet.errors import EgonetError
from egonet.network.depth import DepthNet

LN2 = math.log(2.0)


def test_scale_invariant_loss_by_hand():
    gt = torch.tensor([[[1.0, 1.0, 0.0]]])  # the third pixel has no depth: left out
    pred = torch.log(torch.tensor([[[1.0, 2.0, 5.0]]]))
    # d = [0, ln 2]: mean(d^2) = ln2^2 / 2, mean(d) = ln2 / 2
    assert float(scale_invariant_loss(pred, gt, lam=0.5)) == pytest.approx(LN2**2 / 2 - 0.5 * LN2**2 / 4)
    assert float(scale_invariant_loss(pred, gt, lam=0.0)) == pytest.approx(LN2**2 / 2)
    # A prediction off by one global factor costs nothing at lam = 1, and (1 - lam) * log(factor)^2 otherwise.
    doubled = torch.log(torch.tensor([[[2.0, 2.0, 1.0]]]))
    assert float(scale_invariant_loss(doubled, gt, lam=1.0)) == pytest.approx(0.0, abs=1e-7)
    assert float(scale_invariant_loss(doubled, gt, lam=0.5)) == pytest.approx(0.5 * LN2**2)


def test_scale_invariant_loss_averages_images_with_valid_pixels_and_checks_input():
    gt = torch.tensor([[[1.0, 1.0]], [[0.0, 0.0]]])  # the second image has no valid pixel
    pred = torch.log(torch.tensor([[[1.0, 2.0]], [[9.0, 9.0]]]))
    assert float(scale_invariant_loss(pred, gt, lam=0.0)) == pytest.approx(LN2**2 / 2)
    assert float(scale_invariant_loss(pred, torch.zeros_like(gt))) == 0.0
    with pytest.raises(EgonetError, match="differ"):
        scale_invariant_loss(pred, gt[:, :, :1])
    with pytest.raises(EgonetError, match="lam"):
        scale_invariant_loss(pred, gt, lam=2.0)


def test_depth_errors_by_hand_with_and_without_median_scaling():
    pred = np.array([[1.0, 3.0, 2.0, 0.5]])
    gt = np.array([[1.0, 2.0, 0.0, 1.0]])  # the third pixel has no depth
    e = depth_errors(pred, gt)
    # |p - g| / g = 0, 0.5, 0.5; max ratios 1, 1.5, 2: one under 1.25
    assert (e.abs_rel_sum, e.delta1_hits, e.pixels) == (pytest.approx(1.0), 1, 3)
    assert e.abs_rel == pytest.approx(1 / 3) and e.delta1 == pytest.approx(1 / 3)
    doubled = depth_errors(2 * gt + (gt == 0), gt)
    assert doubled.abs_rel == pytest.approx(1.0) and doubled.delta1 == 0.0
    scaled = depth_errors(2 * gt + (gt == 0), gt, median_scaling=True)
    assert scaled.abs_rel == pytest.approx(0.0) and scaled.delta1 == 1.0


def test_depth_errors_add_up_and_refuse_bad_input():
    total = depth_errors(np.array([[1.0]]), np.array([[1.0]])) + depth_errors(np.array([[2.0]]), np.array([[1.0]]))
    assert total == DepthErrors(1.0, 1, 2) and total.abs_rel == 0.5 and total.delta1 == 0.5
    assert math.isnan(DepthErrors().abs_rel) and depth_errors(np.ones((2, 2)), np.zeros((2, 2))).pixels == 0
    with pytest.raises(EgonetError, match="same"):
        depth_errors(np.ones((2, 2)), np.ones((2, 3)))
    with pytest.raises(EgonetError, match="> 0"):
        depth_errors(np.zeros((1, 1)), np.ones((1, 1)))


def test_assumed_intrinsics_follow_the_field_of_view():
    K = assumed_intrinsics(640, 480, hfov_deg=90.0)
    assert K[0, 0] == pytest.approx(320.0) and K[1, 1] == K[0, 0]
    assert (K[0, 2], K[1, 2]) == (319.5, 239.5)
    # 60 degrees by default: (W / 2) / tan(30 degrees)
    assert assumed_intrinsics(640, 480)[0, 0] == pytest.approx(320 / math.tan(math.radians(30)))
    with pytest.raises(EgonetError, match="hfov_deg"):
        assumed_intrinsics(640, 480, hfov_deg=180.0)
    with pytest.raises(EgonetError, match="width and height"):
        assumed_intrinsics(0, 480)


def test_the_network_gives_log_depth_at_the_input_size():
    net = DepthNet(width=16).eval()
    with torch.no_grad():
        out = net(torch.zeros(2, 3, 50, 70))
    assert out.shape == (2, 1, 50, 70)
    assert torch.allclose(out, torch.full_like(out, 0.4))  # the head starts at log depth 0.4 (about 1.5 m)
    with pytest.raises(EgonetError, match=r"\(N, 3, H, W\)"):
        net(torch.zeros(1, 1, 8, 8))
    with pytest.raises(EgonetError, match="width"):
        DepthNet(width=4)


@pytest.mark.parametrize(("options", "field"), [({"epochs": 0}, "epochs"), ({"width": 8}, "width"),
                                                ({"lr": 0.0}, "lr"), ({"device": "tpu"}, "device")])
def test_bad_settings_name_the_field(options, field):
    with pytest.raises(EgonetError) as info:
        DepthConfig(**options)
    assert info.value.field == field


def _scenes(n: int, seed: int = 0) -> list[DepthSample]:
    """Frames whose depth is brightness: near is bright (a learnable rule), one activity."""
    rng = np.random.default_rng(seed)
    samples = []
    for i in range(n):
        depth = rng.uniform(0.8, 4.0) * np.ones((24, 32), np.float32)
        depth[:, 16:] *= 0.5
        depth[0, 0] = 0.0  # a missing pixel
        rgb = np.repeat((255 / (depth + 0.2))[:, :, None], 3, axis=2).clip(0, 255).astype(np.uint8)
        samples.append(DepthSample(rgb=rgb, depth=depth, key=i, group="room"))
    return samples


def test_fit_depth_records_each_epoch_and_a_checkpoint_the_predictor_reads(tmp_path, one_thread):
    records = []
    config = DepthConfig(epochs=2, width=32, height=24, batch_size=2, net_width=16, device="cpu")
    result = fit_depth(_scenes(5), config, out_path=tmp_path / "depth.pt", on_epoch=records.append)
    assert [r["epoch"] for r in records] == [1, 2] and result.history == records
    assert result.train_keys == [0, 1, 2, 3] and result.test_keys == [4]  # the last 20 % held out
    m = result.metrics
    assert m["test_frames"] == 1 and m["pixels"] == 24 * 32 - 1
    assert 0 <= m["delta1"] <= 1 and m["abs_rel"] >= 0 and 0 <= m["constant_delta1"] <= 1
    train_depths = np.concatenate([s.depth[s.depth > 0] for s in _scenes(5)[:4]])
    assert m["constant_depth_m"] == pytest.approx(float(np.median(train_depths)))
    state = load_checkpoint(tmp_path / "depth.pt")
    assert state["model"]["name"] == DEPTH_MODEL and state["test_keys"] == [4]
    predictor = DepthPredictor(state)
    rgb = _scenes(1, seed=9)[0].rgb
    depth = predictor.predict(np.ascontiguousarray(np.repeat(np.repeat(rgb, 2, 0), 2, 1)))  # any size in, that size out
    assert depth.shape == (48, 64) and depth.dtype == np.float32 and (0.1 <= depth).all() and (depth <= 10).all()


def test_fit_depth_needs_two_frames_and_the_predictor_a_depth_checkpoint():
    with pytest.raises(EgonetError, match="at least two frames"):
        fit_depth(_scenes(1), DepthConfig(epochs=1, device="cpu"))
    with pytest.raises(EgonetError, match="not a depth checkpoint"):
        DepthPredictor({"model": {"name": "egonet-lite"}})
