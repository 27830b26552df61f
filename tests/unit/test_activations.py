"""Each pathway's fc7 averaged over channels (the paper's Figure 3): egonet.network.activations and the predictor."""

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from egonet.errors import EgonetError
from egonet.network.activations import LAYERS, pathways, stream_activations
from egonet.network.builders import build_model
from egonet.predictor import NetworkPredictor


def inputs(h=40, w=56, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(1, 3, h, w, generator=g), torch.rand(1, 3, h, w, generator=g)


@pytest.mark.parametrize(("name", "options"), [("egonet-lite", {}), ("egonet", {"width_divisor": 64})])
def test_the_hook_gives_the_mean_over_channels_of_each_streams_fc7(name, options):
    torch.manual_seed(0)
    model = build_model(name, **options).train()  # the mode is restored afterwards
    rgb, dhg = inputs()
    maps = stream_activations(model, rgb, dhg)
    assert model.training and set(maps) == {"rgb", "dhg"}
    model.eval()
    with torch.no_grad():  # the streams by hand, as TwoStreamEgoNet.grid_logits runs them
        rgb_fc7 = model.rgb_stream(model.rgb_norm(rgb))
        dhg_fc7 = model.dhg_stream(model.dhg_norm(dhg))
    assert rgb_fc7.shape[1] == model.rgb_stream.out_channels and (rgb_fc7 >= 0).all()  # after fc7's ReLU
    torch.testing.assert_close(maps["rgb"], rgb_fc7.mean(dim=1))
    torch.testing.assert_close(maps["dhg"], dhg_fc7.mean(dim=1))
    assert maps["rgb"].shape == rgb_fc7.shape[:1] + rgb_fc7.shape[2:]
    assert not torch.equal(maps["rgb"], maps["dhg"])


def test_one_stream_variants_have_one_pathway_and_the_single_stream_a_joint_one():
    rgb, dhg = inputs()
    only_rgb = build_model("egonet-rgb", width_divisor=64)
    assert list(pathways(only_rgb)) == ["rgb"] and list(stream_activations(only_rgb, rgb, dhg)) == ["rgb"]
    only_dhg = build_model("egonet-dhg", width_divisor=64)
    assert list(stream_activations(only_dhg, rgb, dhg)) == ["dhg"]
    joint = build_model("single-stream", width_divisor=64)
    assert list(stream_activations(joint, rgb, dhg)) == ["joint"]
    assert LAYERS == {"rgb": "fc7", "dhg": "dhg_fc7", "joint": "fc7"}


def test_without_dhg_the_rgb_pathway_runs_alone_and_a_dhg_only_model_refuses():
    torch.manual_seed(1)
    model = build_model("egonet-lite").eval()
    rgb, dhg = inputs()
    alone = stream_activations(model, rgb, None)
    assert list(alone) == ["rgb"]
    torch.testing.assert_close(alone["rgb"], stream_activations(model, rgb, dhg)["rgb"])
    with pytest.raises(EgonetError, match="dhg is required by 'egonet-dhg'"):
        stream_activations(build_model("egonet-dhg", width_divisor=64), rgb, None)
    with pytest.raises(EgonetError, match="rgb must be a torch.Tensor"):
        stream_activations(model, np.zeros((1, 3, 8, 8)), None)


def test_the_predictor_upsamples_each_map_to_the_frame():
    torch.manual_seed(2)
    predictor = NetworkPredictor(build_model("egonet-lite"), size=(32, 48))
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (57, 75, 3), dtype=np.uint8)
    dhg = rng.integers(0, 256, (57, 75, 3), dtype=np.uint8)
    maps = predictor.activations(rgb, dhg)
    assert set(maps) == {"rgb", "dhg"}
    grid = stream_activations(predictor.model, predictor._to_tensor(rgb), predictor._to_tensor(dhg))
    for name, values in maps.items():
        assert values.shape == (57, 75) and values.dtype == np.float32 and (values >= 0).all()
        small = grid[name][0].numpy()
        assert small.shape == (4, 6)  # the 32x48 training size at stride 8
        # corners aligned: the frame's corners are the grid's
        assert np.allclose([values[0, 0], values[-1, -1], values[0, -1]], [small[0, 0], small[-1, -1], small[0, -1]], atol=1e-6)
        expected = F.interpolate(grid[name][:, None], size=(57, 75), mode="bilinear", align_corners=True)[0, 0].numpy()
        np.testing.assert_allclose(values, expected, atol=1e-6)
    assert list(predictor.activations(rgb)) == ["rgb"]
    with pytest.raises(EgonetError, match="dhg must have the shape of rgb"):
        predictor.activations(rgb, dhg[:50])
