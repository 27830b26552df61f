"""Tests for egonet.caffe: reading .caffemodel files without Caffe, and the released conventions.

The files are written by hand (tests/caffe_files.py) in both layouts (current
``layer`` with blob shapes, legacy ``layers`` with num/channels/height/width),
packed and unpacked. The two releases are tested at 1/64 of every width (the
same layer names, kernels and grid: kilobytes, not 270-550 MB), which the
loader accepts only when told to; the full-size shapes are checked on the
meta device, and one slow test reads a full-size RGB release file.
"""

from __future__ import annotations

import hashlib

import cv2
import numpy as np
import pytest
import torch

from egonet import io
from egonet.caffe import RELEASES, checkpoint_from_caffemodel, identify_release, load_caffemodel, read_caffemodel
from egonet.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint
from egonet.network.builders import saved_options
from egonet.predictor import NetworkPredictor
from tests.caffe_files import FULL, TINY, TINY_RELEASES, release_layers, selector_layers, write_caffemodel, write_lying_blob
from tests.realdata import EGONET_SAMPLES

LAYOUTS = [
    pytest.param(False, True, id="current-packed"),
    pytest.param(False, False, id="current-unpacked"),
    pytest.param(True, True, id="legacy-packed"),
    pytest.param(True, False, id="legacy-unpacked"),
]
SIZE = (41, 49)


def uniform(rgb_or_dhg: tuple[float, float, float], size=SIZE) -> torch.Tensor:
    """A (1, 3, H, W) image of one colour in [0, 1]."""
    return torch.tensor(rgb_or_dhg, dtype=torch.float32).view(1, 3, 1, 1).expand(1, 3, *size).contiguous()


def load(tmp_path, layers, *, legacy=False, packed=True, name="model.caffemodel"):
    path = write_caffemodel(tmp_path / name, layers, legacy=legacy, packed=packed)
    return load_caffemodel(path, releases=TINY_RELEASES)


def count(model) -> int:
    return sum(p.numel() for p in model.parameters())


# --------------------------------------------------------------------------- reading


@pytest.mark.parametrize(("legacy", "packed"), LAYOUTS)
def test_reads_names_types_shapes_and_values(tmp_path, legacy, packed):
    weights = np.arange(2 * 3 * 3 * 3, dtype=np.float32).reshape(2, 3, 3, 3) / 7
    bias = np.array([-1.5, 2.25], np.float32)
    path = write_caffemodel(tmp_path / "net.caffemodel", [("data", "Data", []), ("conv", "Convolution", [weights, bias]),
                                                          ("relu", "ReLU", [])], legacy=legacy, packed=packed)
    layers = read_caffemodel(path)
    assert list(layers) == ["data", "conv", "relu"]
    assert (layers["conv"].type, layers["relu"].type, layers["relu"].blobs) == ("Convolution", "ReLU", [])
    read_weights, read_bias = layers["conv"].blobs
    np.testing.assert_array_equal(read_weights, weights)
    # The legacy layout sizes every blob by num, channels, height, width.
    assert read_bias.shape == ((1, 1, 1, 2) if legacy else (2,))
    np.testing.assert_array_equal(read_bias.ravel(), bias)
    assert read_weights.dtype == np.float32
    assert layers["relu"].end == path.stat().st_size


def test_reading_writes_nothing_back_and_reports_progress(tmp_path):
    path = write_caffemodel(tmp_path / "m.caffemodel", release_layers(TINY["rgb"], seed=0))
    before = path.read_bytes()
    seen = []
    layers = read_caffemodel(path, progress=lambda done, total: seen.append((done, total)))
    layers["fc9"].blobs[0][:] = 0  # a private copy-on-write view
    assert path.read_bytes() == before
    assert seen[-1] == (len(before), len(before)) and [d for d, _ in seen] == sorted(d for d, _ in seen)


# --------------------------------------------------------------------------- the released conventions


@pytest.mark.parametrize("key", ["rgb+dhg", "rgb"])
@pytest.mark.parametrize(("legacy", "packed"), LAYOUTS)
def test_the_networks_first_rgb_channel_is_blue(tmp_path, key, legacy, packed):
    first = load(tmp_path, selector_layers(TINY[key], channel=0), legacy=legacy, packed=packed)
    third = load(tmp_path, selector_layers(TINY[key], channel=2), legacy=legacy, packed=packed, name="third.caffemodel")
    dhg = uniform((0.3, 0.3, 0.3))
    blue, red = uniform((0.0, 0.0, 1.0)), uniform((1.0, 0.0, 0.0))
    assert first.config.name == ("egonet" if key == "rgb+dhg" else "egonet-rgb")
    assert torch.all(first.predict(blue, dhg) > first.predict(red, dhg))
    assert torch.all(third.predict(red, dhg) > third.predict(blue, dhg))


@pytest.mark.parametrize(("legacy", "packed"), LAYOUTS)
def test_the_dhg_files_third_channel_reaches_the_network_first(tmp_path, legacy, packed):
    model = load(tmp_path, selector_layers(TINY["rgb+dhg"], stream="dhg", channel=0), legacy=legacy, packed=packed)
    rgb = uniform((0.5, 0.5, 0.5))
    # As the authors' DHG files are read (RGB): gray, height, depth.
    depth_bright, gray_bright = uniform((0.0, 0.0, 1.0)), uniform((1.0, 0.0, 0.0))
    assert torch.all(model.predict(rgb, depth_bright) > model.predict(rgb, gray_bright))
    # The mean the release subtracts from that first channel is depth's (54.21): a depth of exactly
    # that value gives 0 there, so the logit is gain * (0 + 200) + offset = 0 on the grid's inner cell (2, 2).
    depth_at_mean = uniform((0.9, 0.1, 54.21 / 255))
    assert model(rgb, depth_at_mean, geometry="zoom8")[0, 1, 16, 16].abs() < 1e-4
    assert model(rgb, uniform((0.9, 0.1, 60 / 255)), geometry="zoom8")[0, 1, 16, 16] > 0.05


@pytest.mark.parametrize("key", ["rgb+dhg", "rgb"])
@pytest.mark.parametrize(("legacy", "packed"), LAYOUTS[::3])
def test_the_first_coordinate_channel_is_the_row_map(tmp_path, key, legacy, packed):
    rows = load(tmp_path, selector_layers(TINY[key], coordinate=0), legacy=legacy, packed=packed)
    cols = load(tmp_path, selector_layers(TINY[key], coordinate=1), legacy=legacy, packed=packed, name="c.caffemodel")
    rgb, dhg = uniform((0.5, 0.5, 0.5), (386, 514)), uniform((0.5, 0.5, 0.5), (386, 514))
    # The release's own geometry: grid cell i is output row 8 i exactly.
    logits = rows(rgb, dhg, geometry="zoom8").detach()[0, 1]
    assert logits.shape == (385, 513)
    grid = logits[::8, ::8]
    h, w = grid.shape
    assert (h, w) == (49, 65)
    # Caffe's Interp (shrink 8, pad_beg -1) samples image row 1 + i (H - 2) / (h - 1) of row / H * 255 - 127.16.
    y = 1 + torch.arange(h, dtype=torch.float64) * (386 - 2) / (h - 1)
    expected = 0.01 * (y / 386 * 255 - 127.16 + 200) - 2.0
    torch.testing.assert_close(grid[:, 0].double(), expected, atol=1e-4, rtol=0)
    assert float(grid.std(dim=1).max()) < 1e-5  # constant along each row
    col_grid = cols(rgb, dhg, geometry="zoom8").detach()[0, 1][::8, ::8]
    x = 1 + torch.arange(w, dtype=torch.float64) * (514 - 2) / (w - 1)
    torch.testing.assert_close(col_grid[0].double(), 0.01 * (x / 514 * 255 - 127.25 + 200) - 2.0, atol=1e-4, rtol=0)


def test_default_output_is_the_input_size_and_zoom8_the_releases(tmp_path):
    model = load(tmp_path, release_layers(TINY["rgb+dhg"], seed=1))
    rgb, dhg = uniform((0.2, 0.4, 0.6), (386, 514)), uniform((0.5, 0.4, 0.3), (386, 514))
    default, released = model.predict(rgb, dhg), model.predict(rgb, dhg, geometry="zoom8")
    assert default.shape == (1, 386, 514) and released.shape == (1, 385, 513)
    # Both sample the same grid: its first and last cells are the maps' corners.
    for corner in ((0, 0), (-1, -1), (0, -1)):
        torch.testing.assert_close(default[0][corner], released[0][corner])
    with pytest.raises(ValueError, match="geometry"):
        model.predict(rgb, dhg, geometry="caffe")


# --------------------------------------------------------------------------- releases


def test_full_size_release_shapes_are_the_references():
    rgb_dhg, rgb = FULL["rgb+dhg"].expected_shapes(), FULL["rgb"].expected_shapes()
    assert rgb_dhg["fc9"] == [(1024, 8194, 1, 1), (1024,)] and rgb_dhg["fc10_sal"] == [(2, 1024, 1, 1), (2,)]
    assert rgb_dhg["dhg_conv1_1"] == [(64, 3, 3, 3), (64,)] and rgb_dhg["fc6"][0] == (4096, 512, 4, 4)
    assert rgb["fc9"] == [(512, 4098, 1, 1), (512,)] and rgb["fc8_obj"] == [(41, 4096, 1, 1), (41,)]
    assert not any(name.startswith("dhg_") for name in rgb)
    size = {key: sum(int(np.prod(s)) for blobs in shapes.values() for s in blobs) for key, shapes in
            (("rgb+dhg", rgb_dhg), ("rgb", rgb))}
    # The reference's parameter counts: 138,502,786, and 67,154,242 without fc8_obj (41 x 4096 + 41 more).
    assert size == {"rgb+dhg": 138_502_786, "rgb": 67_154_242 + 41 * 4096 + 41}
    with torch.device("meta"):
        assert count(FULL["rgb"].build()) == 67_154_242 and count(FULL["rgb+dhg"].build()) == 138_502_786


def test_the_rgb_release_is_recognised_and_fc8_obj_ignored(tmp_path):
    values = {"fc8_obj": [np.full((41, 64, 1, 1), 9.0, np.float32), np.full(41, 9.0, np.float32)]}
    layers = release_layers(TINY["rgb"], values)
    model = load(tmp_path, layers)
    assert model.config.name == "egonet-rgb" and model.config.options["fc9_width"] == 512
    assert not model.uses_dhg and model.config.options["coords"] == "released"
    with torch.device("meta"):
        assert count(model) == count(TINY["rgb"].build())
    assert not any("fc8" in name for name in model.state_dict())
    rgb = uniform((0.1, 0.2, 0.3))
    torch.testing.assert_close(model.predict(rgb, None), model.predict(rgb, uniform((0.9, 0.1, 0.5))))


def test_weights_land_in_the_layers_of_their_names(tmp_path):
    layers = release_layers(TINY["rgb+dhg"], seed=3)
    model = load(tmp_path, layers)
    blobs = {name: b for name, _, b in layers}
    np.testing.assert_array_equal(model.dhg_stream.layers.conv1_1.weight.detach().numpy(), blobs["dhg_conv1_1"][0])
    np.testing.assert_array_equal(model.rgb_stream.layers.fc7.bias.detach().numpy(), blobs["fc7"][1])
    np.testing.assert_array_equal(model.head.fc9.weight.detach().numpy(), blobs["fc9"][0])
    np.testing.assert_array_equal(model.head.fc10.bias.detach().numpy(), blobs["fc10_sal"][1])
    assert not model.training


def refused(tmp_path, layers, **kwargs) -> str:
    path = write_caffemodel(tmp_path / "bad.caffemodel", layers)
    with pytest.raises(ValueError) as info:
        load_caffemodel(path, **kwargs)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    return message


def test_refuses_a_missing_layer_a_wrong_shape_and_extra_weights(tmp_path):
    layers = release_layers(TINY["rgb+dhg"])
    missing = [layer for layer in layers if layer[0] != "fc9"]
    assert "layer 'fc9' is missing" in refused(tmp_path, missing, releases=TINY_RELEASES)
    wrong = [(n, t, [np.zeros((16, 129, 1, 1), np.float32), b[1]] if n == "fc9" else b) for n, t, b in layers]
    assert ("layer 'fc9' weights have shape (16, 129, 1, 1) in the file, (16, 130, 1, 1) in the authors' RGB+DHG "
            "release at 1/64 width") in refused(tmp_path, wrong, releases=TINY_RELEASES)
    extra = [*layers, ("fc8_obj", "Convolution", [np.zeros((41, 64, 1, 1), np.float32), np.zeros(41, np.float32)])]
    assert "layer 'fc8_obj' has weights" in refused(tmp_path, extra, releases=TINY_RELEASES)


def test_refuses_the_paper_sized_rgb_model_naming_both_fc9_shapes(tmp_path):
    # The paper's RGB ablation has a 1024-wide fc9 (16 at 1/64), the release 512 (8).
    layers = [(n, t, [np.zeros((16, 66, 1, 1), np.float32), np.zeros(16, np.float32)] if n == "fc9" else b)
              for n, t, b in release_layers(TINY["rgb"])]
    assert refused(tmp_path, layers, releases=TINY_RELEASES).endswith(
        "not the authors' RGB release at 1/64 width: layer 'fc9' weights have shape (16, 66, 1, 1) in the file, "
        "(8, 66, 1, 1) in the authors' RGB release at 1/64 width"
    )


def test_the_authors_releases_refuse_a_small_file_of_the_same_names(tmp_path):
    message = refused(tmp_path, release_layers(TINY["rgb+dhg"]))
    assert message.endswith(
        "not the authors' RGB+DHG release: layer 'conv1_1' weights have shape (1, 3, 3, 3) in the file, "
        "(64, 3, 3, 3) in the authors' RGB+DHG release"
    )
    assert "not the authors' RGB release: layer 'conv1_1'" in refused(tmp_path, release_layers(TINY["rgb"]))


def test_refuses_truncated_damaged_empty_and_other_files(tmp_path):
    good = write_caffemodel(tmp_path / "good.caffemodel", release_layers(TINY["rgb+dhg"], seed=0))
    data = good.read_bytes()
    cut = tmp_path / "cut.caffemodel"
    cut.write_bytes(data[: len(data) - 100])
    with pytest.raises(ValueError, match=r"truncated: the file ends inside the layer after 'fc9'"):
        read_caffemodel(cut)
    empty = tmp_path / "empty.caffemodel"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match="is empty"):
        load_caffemodel(empty)
    text = tmp_path / "deploy.prototxt"
    text.write_text('name: "EgoNet"\nlayer { name: "data" type: "Input" }\n')
    with pytest.raises(ValueError, match="not a Caffe .caffemodel"):
        load_caffemodel(text)
    with pytest.raises(ValueError, match="cannot read"):
        load_caffemodel(tmp_path / "absent.caffemodel")
    short = write_caffemodel(tmp_path / "short.caffemodel", [("conv", "Convolution", [np.zeros((2, 3), np.float32)])])
    damaged = bytearray(short.read_bytes())
    damaged[damaged.index(bytes([0x0A, 2, 2, 3])) + 3] = 4  # the shape says (2, 4): 8 values, 6 given
    (tmp_path / "damaged.caffemodel").write_bytes(bytes(damaged))
    with pytest.raises(ValueError, match=r"layer 'conv' blob 0 holds 6 values, its shape \(2, 4\) needs 8"):
        read_caffemodel(tmp_path / "damaged.caffemodel")


@pytest.mark.parametrize("dims", [[2**63, 0], [2**64 - 1, 0], [2**40, 2**40, 0]])
def test_refuses_a_blob_of_an_impossible_shape_naming_the_file_as_given(tmp_path, dims):
    """Review: a blob shape of 2**63 (no data) escaped as numpy's ValueError. Messages name the file as its user knows it."""
    lie = write_lying_blob(tmp_path / "1f3a-upload.caffemodel", dims)
    with pytest.raises(ValueError, match=r"^lie.caffemodel: its first layer has a blob of an impossible shape") as caught:
        read_caffemodel(lie, name="lie.caffemodel")
    assert str(tmp_path) not in str(caught.value)
    with pytest.raises(ValueError, match=r"^lie.caffemodel: its first layer"):
        checkpoint_from_caffemodel(lie, releases=TINY_RELEASES, name="lie.caffemodel")


def test_identify_release_uses_dhg_layers_to_choose_the_closest(tmp_path):
    layers = read_caffemodel(write_caffemodel(tmp_path / "x.caffemodel", release_layers(TINY["rgb+dhg"])))
    assert identify_release(layers, releases=TINY_RELEASES).key == "rgb+dhg"
    del layers["dhg_fc7"]
    with pytest.raises(ValueError, match="not the authors' RGB\\+DHG release at 1/64 width: layer 'dhg_fc7' is missing"):
        identify_release(layers, releases=TINY_RELEASES)


# --------------------------------------------------------------------------- checkpoints and predicting


def test_checkpoint_predicts_through_the_one_predictor(tmp_path):
    path = write_caffemodel(tmp_path / "m.caffemodel", release_layers(TINY["rgb+dhg"], seed=2))
    seen = []
    state = checkpoint_from_caffemodel(path, size=(48, 64), releases=TINY_RELEASES,
                                       progress=lambda done, total: seen.append(done / total))
    assert seen[-1] == 1.0
    assert state["released"]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert state["released"]["release"] == "rgb+dhg" and state["fold"] == "released"
    save_checkpoint(tmp_path / "released.pt", state)
    again = load_checkpoint(tmp_path / "released.pt")
    assert saved_options(again["model"]["name"], again["model"]["options"]) == again["model"]["options"]
    model = model_from_checkpoint(again)
    direct = load_caffemodel(path, releases=TINY_RELEASES)
    rgb = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    dhg = np.random.default_rng(1).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    predicted = NetworkPredictor.from_checkpoint(again).predict(rgb, dhg)
    expected = direct.predict(torch.from_numpy(rgb).permute(2, 0, 1)[None] / 255, torch.from_numpy(dhg).permute(2, 0, 1)[None] / 255)[0]
    np.testing.assert_allclose(predicted, expected.numpy(), atol=1e-5)
    assert model.config == direct.config


@pytest.mark.skipif(not EGONET_SAMPLES.exists(), reason="shared data not present")
@pytest.mark.parametrize("key", ["rgb+dhg", "rgb"])
def test_the_authors_frames_give_finite_maps_of_their_size(tmp_path, key):
    model = load(tmp_path, release_layers(TINY[key], seed=4))
    for rgb_path in sorted((EGONET_SAMPLES / "rgb").glob("*.jpg")):
        rgb = io.read_image(rgb_path)
        dhg = io.read_dhg(EGONET_SAMPLES / "dhg" / rgb_path.name)
        to_tensor = lambda a: torch.from_numpy(a).permute(2, 0, 1)[None].float() / 255  # noqa: E731
        probability = model.predict(to_tensor(rgb), to_tensor(dhg))
        assert probability.shape == (1, *rgb.shape[:2]) == (1, 386, 514)
        assert torch.isfinite(probability).all() and float(probability.std()) > 0
        assert model.predict(to_tensor(rgb), to_tensor(dhg), geometry="zoom8").shape == (1, 385, 513)
        # The predictor runs it too (numpy in, numpy out at the frame's size).
        out = NetworkPredictor(model, size=(386, 514)).predict(rgb, dhg)
        assert out.shape == (386, 514) and np.isfinite(out).all()
        assert cv2.imread(str(rgb_path)) is not None


@pytest.mark.slow
def test_a_full_size_rgb_release_file(full_rgb_caffemodel):
    path, marker = full_rgb_caffemodel
    seen = []
    model = load_caffemodel(path, progress=lambda done, total: seen.append((done, total)))
    assert seen[-1] == (path.stat().st_size, path.stat().st_size)
    assert model.config.name == "egonet-rgb" and count(model) == 67_154_242
    np.testing.assert_array_equal(model.head.fc9.bias.detach().numpy(), marker)
    assert model.predict(uniform((0.5, 0.5, 0.5), (33, 41)), None).shape == (1, 33, 41)
