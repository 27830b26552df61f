"""Tests for egonet.init: torchvision VGG16 / DeepLab blobs -> EgoNet's VGG streams.

Small synthetic state dicts with torchvision's key names check the
conversion by hand; full-size ones are made of expanded (stride-0) tensors,
which cost no memory and save to a few kilobytes, so the shape checks run
against the real models on the ``meta`` device. The tests that copy into a
real 65-138 M parameter model are marked slow.
"""

from __future__ import annotations

import hashlib

import pytest
import torch
import torch.nn.functional as F

from egonet.init import (
    DEEPLAB_LAYERS,
    TORCHVISION_CONVS,
    TORCHVISION_MEAN,
    TORCHVISION_STD,
    check_init,
    deeplab_layers,
    initialise,
    load_init,
    vgg16_to_deeplab,
)
from egonet.network.builders import build_model
from egonet.network.streams import RELEASED_BGR_MEAN

# (in, out) of the 13 convolutions at full VGG16 size.
VGG16_WIDTHS = [(3, 64), (64, 64), (64, 128), (128, 128), (128, 256), (256, 256), (256, 256),
                (256, 512), (512, 512), (512, 512), (512, 512), (512, 512), (512, 512)]


def tiny_vgg16(seed: int = 0, fc: int = 6) -> dict[str, torch.Tensor]:
    """A torchvision-keyed VGG16 with narrow layers (random values), fc6 over 4 x 7 x 7 inputs."""
    g = torch.Generator().manual_seed(seed)
    widths = [(3, 2), (2, 2), (2, 3), (3, 3), (3, 3), (3, 3), (3, 3), (3, 4), (4, 4), (4, 4), (4, 4), (4, 4), (4, 4)]
    sd = {}
    for index, (cin, cout) in zip(TORCHVISION_CONVS, widths, strict=True):
        sd[f"features.{index}.weight"] = torch.randn(cout, cin, 3, 3, generator=g)
        sd[f"features.{index}.bias"] = torch.randn(cout, generator=g)
    sd["classifier.0.weight"] = torch.randn(fc, 4 * 49, generator=g)
    sd["classifier.0.bias"] = torch.randn(fc, generator=g)
    sd["classifier.3.weight"] = torch.randn(fc, fc, generator=g)
    sd["classifier.3.bias"] = torch.randn(fc, generator=g)
    sd["classifier.6.weight"] = torch.randn(10, fc, generator=g)  # fc8: ignored
    sd["classifier.6.bias"] = torch.randn(10, generator=g)
    return sd


def full_vgg16() -> dict[str, torch.Tensor]:
    """torchvision VGG16's shapes, each tensor a stride-0 view of a small one (no memory, a tiny file).

    Every fc6 input position holds its tap index within the 7x7 window (0..48), so
    which taps were kept shows in the values.
    """
    sd = {}
    for k, (index, (cin, cout)) in enumerate(zip(TORCHVISION_CONVS, VGG16_WIDTHS, strict=True)):
        sd[f"features.{index}.weight"] = (torch.arange(9.0) * (k + 1)).view(1, 1, 3, 3).expand(cout, cin, 3, 3)
        sd[f"features.{index}.bias"] = torch.full((1,), float(k)).expand(cout)
    # (4096, 25088): one 100 KB row (0..48 for each of the 512 channels), repeated by a stride-0 view.
    sd["classifier.0.weight"] = torch.arange(49.0).repeat(512).view(1, -1).expand(4096, -1)
    sd["classifier.0.bias"] = torch.full((1,), 6.0).expand(4096)
    sd["classifier.3.weight"] = torch.full((1, 1), 7.0).expand(4096, 4096)
    sd["classifier.3.bias"] = torch.full((1,), 8.0).expand(4096)
    return sd


# --------------------------------------------------------------------------- conversion by hand


def test_fc6_keeps_every_other_tap_and_fc7_becomes_1x1():
    sd = tiny_vgg16()
    layers = vgg16_to_deeplab(sd)
    assert list(layers) == list(DEEPLAB_LAYERS)
    w7 = sd["classifier.0.weight"].view(6, 4, 7, 7)
    fc6, bias6 = layers["fc6"]
    assert fc6.shape == (6, 4, 4, 4)
    for i, row in enumerate((0, 2, 4, 6)):
        for j, col in enumerate((0, 2, 4, 6)):
            torch.testing.assert_close(fc6[:, :, i, j], w7[:, :, row, col])
    torch.testing.assert_close(bias6, sd["classifier.0.bias"])
    fc7, _ = layers["fc7"]
    assert fc7.shape == (6, 6, 1, 1)
    torch.testing.assert_close(fc7[:, :, 0, 0], sd["classifier.3.weight"])
    # The other convolutions are copied unchanged.
    torch.testing.assert_close(layers["conv3_2"][0], sd["features.12.weight"])
    torch.testing.assert_close(layers["conv5_3"][1], sd["features.28.bias"])


def test_conv1_1_answers_our_input_as_torchvision_answers_its_own():
    # The same 0-255 RGB image through torchvision's normalisation and weights, and
    # through ours (BGR minus the Caffe means) with the converted weights: the same
    # responses wherever the 3x3 window holds no padding.
    sd = tiny_vgg16(seed=3)
    weight, bias = vgg16_to_deeplab(sd)["conv1_1"]
    v = torch.rand(1, 3, 9, 11, generator=torch.Generator().manual_seed(1)) * 255
    mean, std = torch.tensor(TORCHVISION_MEAN).view(1, 3, 1, 1), torch.tensor(TORCHVISION_STD).view(1, 3, 1, 1)
    theirs = F.conv2d((v / 255 - mean) / std, sd["features.0.weight"], sd["features.0.bias"])
    ours_input = v.flip(1) - torch.tensor(RELEASED_BGR_MEAN).view(1, 3, 1, 1)
    ours = F.conv2d(ours_input, weight, bias)
    torch.testing.assert_close(ours, theirs, rtol=1e-4, atol=1e-4)


def test_caffemodel_blobs_chain_and_dhg_layers_are_used_when_present():
    sd = tiny_vgg16()
    layers = vgg16_to_deeplab(sd)
    blobs = {name: [w.numpy(), b.numpy()] for name, (w, b) in layers.items()}
    same, dhg = deeplab_layers(blobs)
    assert dhg is None
    torch.testing.assert_close(same["fc6"][0], layers["fc6"][0])
    both = blobs | {f"dhg_{name}": [w * 2, b] for name, (w, b) in blobs.items()} | {"fc9": [None]}
    rgb, dhg = deeplab_layers(both)
    torch.testing.assert_close(dhg["conv4_1"][0], 2 * rgb["conv4_1"][0])


def test_plain_vgg_caffemodel_with_dense_fc6_is_subsampled():
    sd = tiny_vgg16()
    blobs = {name: [sd[f"features.{i}.weight"].numpy(), sd[f"features.{i}.bias"].numpy()]
             for name, i in zip(DEEPLAB_LAYERS, TORCHVISION_CONVS, strict=False)}
    blobs["fc6"] = [sd["classifier.0.weight"].numpy(), sd["classifier.0.bias"].numpy()]
    blobs["fc7"] = [sd["classifier.3.weight"].numpy(), sd["classifier.3.bias"].numpy()]
    layers, _ = deeplab_layers(blobs)
    torch.testing.assert_close(layers["fc6"][0], sd["classifier.0.weight"].view(6, 4, 7, 7)[:, :, ::2, ::2])
    # A caffemodel is already in Caffe's convention: conv1_1 is not rewritten.
    torch.testing.assert_close(layers["conv1_1"][0], sd["features.0.weight"])


# --------------------------------------------------------------------------- errors name the key/layer and shapes


def test_missing_key_is_named():
    sd = tiny_vgg16()
    del sd["features.17.weight"]
    with pytest.raises(ValueError, match=r"no 'features.17.weight'.*torchvision VGG16"):
        vgg16_to_deeplab(sd, source="x.pth")


def test_fc6_of_wrong_width_names_key_and_shapes():
    sd = tiny_vgg16()
    sd["classifier.0.weight"] = torch.zeros(6, 4 * 36)
    with pytest.raises(ValueError, match=r"classifier.0 weight has shape \(6, 144\), fc6 needs \(O, 4 x 7 x 7 = 196\)"):
        vgg16_to_deeplab(sd)


def test_largefov_caffemodel_is_refused_with_shapes():
    layers = vgg16_to_deeplab(tiny_vgg16())
    blobs = {name: [w.numpy(), b.numpy()] for name, (w, b) in layers.items()}
    blobs["fc6"] = [torch.zeros(1024, 4, 3, 3).numpy(), torch.zeros(1024).numpy()]
    with pytest.raises(ValueError, match=r"fc6 weight has shape \(1024, 4, 3, 3\).*LargeFOV"):
        deeplab_layers(blobs, source="deeplab_largefov.caffemodel")
    del blobs["conv2_1"]
    with pytest.raises(ValueError, match="layer 'conv2_1' is missing"):
        deeplab_layers(blobs)


def test_small_file_does_not_fit_the_model_and_says_where(tmp_path):
    path = tmp_path / "vgg16-tiny.pth"
    torch.save(tiny_vgg16(), path)
    with torch.device("meta"):
        model = build_model("egonet")
    weights = load_init(path)
    with pytest.raises(ValueError, match=r"vgg16-tiny.pth: layer conv1_1 has weight \(2, 3, 3, 3\).*rgb_stream.conv1_1 needs \(64, 3, 3, 3\)"):
        check_init(model, weights)


def test_unreadable_missing_and_lite_are_refused(tmp_path):
    with pytest.raises(ValueError, match="no such file"):
        load_init(tmp_path / "absent.pth")
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="junk.pth: cannot read it as a PyTorch state dict"):
        load_init(junk)
    listed = tmp_path / "list.pth"
    torch.save([torch.zeros(1)], listed)
    with pytest.raises(ValueError, match="expected a VGG16 state dict"):
        load_init(listed)
    with torch.device("meta"):
        lite = build_model("egonet-lite")
    torch.save(full_vgg16(), tmp_path / "vgg16.pth")
    with pytest.raises(ValueError, match="'egonet-lite' has no VGG stream.*--pretrained"):
        check_init(lite, load_init(tmp_path / "vgg16.pth"))


# --------------------------------------------------------------------------- full-size files


def test_full_size_file_is_small_hashed_and_fits_every_vgg_model(tmp_path):
    path = tmp_path / "vgg16-00000000.pth"
    torch.save(full_vgg16(), path)
    assert path.stat().st_size < 2_000_000  # stride-0 views save their small storage
    weights = load_init(path)
    assert weights.record() == {
        "name": "vgg16-00000000.pth", "sha256": hashlib.sha256(path.read_bytes()).hexdigest(), "kind": "torchvision-vgg16",
    }
    fc6 = weights.layers["fc6"][0]
    assert fc6.shape == (4096, 512, 4, 4)
    # Taps (row, col) kept: (0, 0) = 0, (0, 2) = 2, (2, 0) = 14, (6, 6) = 48.
    assert [float(fc6[5, 7, i, j]) for i, j in ((0, 0), (0, 1), (1, 0), (3, 3))] == [0.0, 2.0, 14.0, 48.0]
    expected = {
        "egonet": ["rgb_stream", "dhg_stream"], "egonet-rgb": ["rgb_stream"], "egonet-dhg": ["dhg_stream"],
        "no-coords": ["rgb_stream", "dhg_stream"], "no-embedding": ["rgb_stream", "dhg_stream"],
        "single-stream": ["stream"], "deeplab-rgb": ["rgb_stream"], "deeplab-dhg": ["dhg_stream"],
    }
    for name, streams in expected.items():
        with torch.device("meta"):
            model = build_model(name)
        assert check_init(model, weights) == streams


def test_sha256_mismatch_is_refused(tmp_path):
    path = tmp_path / "vgg16.pth"
    torch.save(full_vgg16(), path)
    with torch.device("meta"):
        model = build_model("deeplab-rgb")
    with pytest.raises(ValueError, match="differs from the recorded 000000000000"):
        initialise(model, path, sha256="0" * 64)


@pytest.mark.slow
def test_initialise_copies_into_both_streams_of_egonet(tmp_path):
    path = tmp_path / "vgg16.pth"
    torch.save(full_vgg16(), path)
    torch.manual_seed(0)
    model = build_model("egonet")
    head_before = model.head.fc9.weight[:3, :3].clone()
    initialise(model, path)
    model.requires_grad_(False)
    for stream in (model.rgb_stream, model.dhg_stream):
        layers = stream.layers
        assert float(layers.fc6.weight[9, 3, 3, 3]) == 48.0 and float(layers.fc6.bias[0]) == 6.0
        assert float(layers.fc7.weight[1, 2, 0, 0]) == 7.0
        torch.testing.assert_close(layers.conv3_3.weight[0, 0], torch.arange(9.0).view(3, 3) * 7)
        assert float(layers.conv1_2.bias[5]) == 1.0
    torch.testing.assert_close(model.rgb_stream.layers.conv1_1.weight, model.dhg_stream.layers.conv1_1.weight)
    torch.testing.assert_close(model.head.fc9.weight[:3, :3], head_before)  # the head stays random

    early = build_model("single-stream").requires_grad_(False)
    initialise(early, path)
    conv = early.stream.layers.conv1_1.weight
    torch.testing.assert_close(conv[:, :3], conv[:, 3:6])
    torch.testing.assert_close(conv[:, :3] * 2, model.rgb_stream.layers.conv1_1.weight)
    assert float(conv[:, 6:].abs().max()) == 0.0


# --------------------------------------------------------------------------- the training hook


def test_initialised_run_takes_the_papers_lr_converted_to_the_mean_loss():
    from egonet.checkpoint import DEFAULT_LR, TrainConfig, paper_lr

    assert paper_lr(height=481, width=641) == pytest.approx(0.308, abs=1e-3)  # 1e-6 x 481 x 641
    config = TrainConfig(model="egonet", init="vgg16.pth", height=240, width=320)
    assert config.learning_rate == pytest.approx(1e-6 * 240 * 320)
    assert TrainConfig(model="egonet", height=240, width=320).learning_rate == DEFAULT_LR["egonet"]
    assert TrainConfig(model="egonet", init="vgg16.pth", lr=0.01).learning_rate == 0.01
    assert TrainConfig.from_dict(config.to_dict()).init == "vgg16.pth"
    with pytest.raises(ValueError, match="init must be a file name and excludes pretrained"):
        TrainConfig(model="egonet-lite", init="vgg16.pth", pretrained=True)


def test_an_egonet_caffemodel_gives_the_dhg_stream_its_own_layers():
    from egonet.init import InitWeights

    layers = vgg16_to_deeplab(full_vgg16())
    narrow = vgg16_to_deeplab(tiny_vgg16())  # the DHG stream's layers, of other shapes
    weights = InitWeights("egonet.caffemodel", "0" * 64, "deeplab-caffemodel", layers, narrow)
    with torch.device("meta"):
        rgb_only, with_dhg = build_model("egonet-rgb"), build_model("egonet")
    assert check_init(rgb_only, weights) == ["rgb_stream"]  # the RGB layers fit
    with pytest.raises(ValueError, match=r"egonet's dhg_stream.conv1_1 needs \(64, 3, 3, 3\)"):
        check_init(with_dhg, weights)  # the DHG stream reads the dhg_ layers


@pytest.mark.parametrize("legacy", [False, True])
def test_a_deeplab_caffemodel_file_initialises_both_streams(tmp_path, legacy):
    """A hand-built DeepLab file (1/64 widths, both layouts) read by egonet.caffe goes into every VGG stream."""
    from egonet.caffe import model_layers
    from tests.caffe_files import write_caffemodel

    model = build_model("egonet", width_divisor=64).requires_grad_(False)
    convs = {name: conv for name, conv in model_layers(model).items() if not name.startswith(("dhg_", "fc9", "fc10"))}
    g = torch.Generator().manual_seed(3)
    values = {name: (torch.randn(conv.weight.shape, generator=g), torch.randn(conv.bias.shape, generator=g))
              for name, conv in convs.items()}
    layers = [(name, "Convolution", [w.numpy(), b.numpy()]) for name, (w, b) in values.items()]
    path = write_caffemodel(tmp_path / "deeplab.caffemodel", layers, legacy=legacy, packed=not legacy)
    weights = initialise(model, path)
    assert weights.kind == "deeplab-caffemodel" and weights.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    for stream in (model.rgb_stream, model.dhg_stream):
        for name, (w, b) in values.items():
            torch.testing.assert_close(getattr(stream.layers, name).weight, w)
            torch.testing.assert_close(getattr(stream.layers, name).bias, b)


def test_a_legacy_vgg16_caffemodel_with_dense_fc_layers_is_converted(tmp_path):
    """A plain VGG16 .caffemodel (legacy layout: inner products stored (1, 1, O, I)) converts like torchvision's."""
    from tests.caffe_files import write_caffemodel

    sd = tiny_vgg16()
    layers = []
    for name, index in zip(DEEPLAB_LAYERS[:13], TORCHVISION_CONVS, strict=True):
        layers.append((name, "Convolution", [sd[f"features.{index}.weight"].numpy(), sd[f"features.{index}.bias"].numpy()]))
    for name, key in (("fc6", "classifier.0"), ("fc7", "classifier.3")):
        weight = sd[f"{key}.weight"].numpy()
        layers.append((name, "InnerProduct", [weight.reshape(1, 1, *weight.shape), sd[f"{key}.bias"].numpy()]))
    path = write_caffemodel(tmp_path / "vgg16.caffemodel", layers, legacy=True)
    got = load_init(path)
    fc6 = got.layers["fc6"][0]
    assert tuple(fc6.shape) == (6, 4, 4, 4)
    torch.testing.assert_close(fc6, sd["classifier.0.weight"].reshape(6, 4, 7, 7)[:, :, ::2, ::2])
    assert tuple(got.layers["fc7"][0].shape) == (6, 6, 1, 1)
