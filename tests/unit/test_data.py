"""Tests for egonet.data: samples from arrays and files, the training size, paired augmentation."""

import numpy as np
import pytest
import torch

from egonet import io
from egonet.data import (
    Augment,
    FrameDataset,
    Sample,
    augment_frame,
    load_sample,
    resize_frame,
)

NO_COLOUR = {"brightness": 0.0, "contrast": 0.0, "saturation": 0.0}


def frame(h=24, w=32, seed=0):
    rng = np.random.default_rng(seed)
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    dhg = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    mask = np.zeros((h, w), bool)
    mask[h // 4 : h // 2, w // 3 : w // 2] = True
    return rgb, dhg, mask


def block_frame(h=48, w=64):
    """RGB = DHG = white where the mask is: a transform applied alike keeps them in register."""
    mask = np.zeros((h, w), bool)
    mask[10:30, 20:50] = True
    image = np.repeat(mask[..., None] * np.uint8(255), 3, axis=2)
    return image, image.copy(), mask


def test_a_sample_from_arrays_is_checked_and_returned_as_is():
    rgb, dhg, mask = frame()
    got = load_sample(Sample(rgb=rgb, dhg=dhg, mask=mask))
    assert all(np.array_equal(a, b) for a, b in zip(got, (rgb, dhg, mask), strict=True))


def test_a_sample_from_files_reads_them(tmp_path):
    rgb, dhg, mask = frame()
    for name, image in (("rgb.png", rgb), ("dhg.png", dhg), ("mask.png", mask)):
        (tmp_path / name).write_bytes(io.encode_png(image))
    got_rgb, got_dhg, got_mask = load_sample(Sample(rgb=tmp_path / "rgb.png", dhg=str(tmp_path / "dhg.png"), mask=tmp_path / "mask.png"))
    assert np.array_equal(got_rgb, rgb) and np.array_equal(got_dhg, dhg) and np.array_equal(got_mask, mask)


def test_no_mask_means_no_action_object_and_no_dhg_gives_zeros():
    rgb, _, _ = frame()
    data = FrameDataset([Sample(rgb=rgb, dhg=None, mask=None)], size=(12, 16))
    item = data[0]
    assert item["mask"].sum() == 0 and item["dhg"].abs().sum() == 0
    assert load_sample(Sample(rgb=rgb, dhg=None, mask=None))[1] is None


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"rgb": np.zeros((24, 32, 3), np.float32)}, "rgb must be a uint8"),
        ({"dhg": np.zeros((20, 32, 3), np.uint8)}, "dhg is 32x20, the RGB frame 32x24"),
        ({"mask": np.zeros((24, 32), np.uint8)}, "mask must be a bool"),
        ({"mask": np.zeros((24, 30), bool)}, "mask is 30x24"),
        ({"rgb": np.zeros((4, 32, 3), np.uint8)}, "at least 8x8"),
    ],
)
def test_bad_samples_are_refused_naming_the_frame(change, message):
    rgb, dhg, mask = frame()
    sample = Sample(**({"rgb": rgb, "dhg": dhg, "mask": mask} | change), key=17)
    with pytest.raises(ValueError, match=message) as info:
        load_sample(sample)
    assert "sample 17" in str(info.value)


def test_a_missing_file_names_the_file(tmp_path):
    with pytest.raises(io.MediaError, match="nope.png"):
        load_sample(Sample(rgb=tmp_path / "nope.png", dhg=None, mask=None))


def test_dataset_arguments_are_checked():
    rgb, dhg, mask = frame()
    with pytest.raises(ValueError, match="samples is empty"):
        FrameDataset([], size=(24, 32))
    with pytest.raises(ValueError, match="size must be"):
        FrameDataset([Sample(rgb, dhg, mask)], size=(4, 32))
    with pytest.raises(ValueError, match=r"samples\[0\] must be"):
        FrameDataset([(rgb, dhg, mask)], size=(24, 32))
    with pytest.raises(ValueError, match="max_zoom"):
        Augment(max_zoom=0.5)
    with pytest.raises(ValueError, match="brightness"):
        Augment(brightness=1.5)


def test_items_are_at_the_training_size_in_zero_one_with_binary_masks():
    rgb, dhg, mask = frame(48, 64)
    data = FrameDataset([Sample(rgb, dhg, mask)], size=(24, 32), augment=Augment(), seed=3)
    item = data[0]
    assert item["rgb"].shape == item["dhg"].shape == (3, 24, 32)
    assert item["rgb"].dtype == torch.float32 and 0 <= item["rgb"].min() and item["rgb"].max() <= 1
    assert item["mask"].dtype == torch.int64 and set(item["mask"].unique().tolist()) <= {0, 1}


def test_masks_resize_with_nearest_neighbour_and_images_with_area():
    mask = np.zeros((4, 4), bool)
    mask[:2, :2] = True
    assert np.array_equal(resize_frame(mask, (2, 2), nearest=True), [[True, False], [False, False]])
    image = np.zeros((2, 2, 3), np.uint8)
    image[0, 0] = 200
    assert resize_frame(image, (1, 1))[0, 0, 0] == 50  # the mean of the 2x2 block


def test_one_geometric_transform_moves_rgb_dhg_and_mask_alike():
    rgb, dhg, mask = block_frame()
    augment = Augment(max_zoom=1.6, flip=True, **NO_COLOUR)
    for seed in range(10):
        out_rgb, out_dhg, out_mask = augment_frame(rgb, dhg, mask, augment, np.random.default_rng(seed))
        assert out_rgb.shape == rgb.shape and out_mask.dtype == bool
        assert np.array_equal(out_rgb, out_dhg)
        # The mask (nearest) and the image (bilinear) agree but for a one-pixel border.
        assert np.mean(out_mask == (out_rgb[..., 0] > 127)) > 0.97


def test_flip_mirrors_all_three_exactly_without_zoom():
    rgb, dhg, mask = frame(seed=1)
    augment = Augment(max_zoom=1.0, flip=True, **NO_COLOUR)
    seen = set()
    for seed in range(12):
        out_rgb, out_dhg, out_mask = augment_frame(rgb, dhg, mask, augment, np.random.default_rng(seed))
        flipped = np.array_equal(out_mask, mask[:, ::-1])
        assert flipped or np.array_equal(out_mask, mask)
        source = (rgb[:, ::-1], dhg[:, ::-1]) if flipped else (rgb, dhg)
        assert np.array_equal(out_rgb, source[0]) and np.array_equal(out_dhg, source[1])
        seen.add(flipped)
    assert seen == {True, False}


def test_colour_changes_touch_rgb_only():
    rgb, dhg, mask = frame()
    augment = Augment(max_zoom=1.0, flip=False, brightness=0.5, contrast=0.5, saturation=0.5)
    out_rgb, out_dhg, out_mask = augment_frame(rgb, dhg, mask, augment, np.random.default_rng(0))
    assert not np.array_equal(out_rgb, rgb)
    assert np.array_equal(out_dhg, dhg) and np.array_equal(out_mask, mask)


def test_augmentation_is_a_function_of_seed_epoch_and_frame():
    rgb, dhg, mask = frame(48, 64)
    samples = [Sample(rgb, dhg, mask, key=i) for i in range(2)]

    def item(seed, epoch, index):
        data = FrameDataset(samples, size=(24, 32), augment=Augment(max_zoom=2.0), seed=seed)
        data.set_epoch(epoch)
        return data[index]["rgb"]

    assert torch.equal(item(0, 1, 0), item(0, 1, 0))
    assert not torch.equal(item(0, 1, 0), item(0, 2, 0))
    assert not torch.equal(item(0, 1, 0), item(1, 1, 0))
    assert not torch.equal(item(0, 1, 0), item(0, 1, 1))


def test_subsets_share_the_cache_and_keep_their_own_augmentation():
    samples = [Sample(*frame(seed=i), group="ab"[i % 2], key=i) for i in range(4)]
    data = FrameDataset(samples, size=(12, 16))
    train = data.subset([0, 2], augment=Augment())
    test = data.subset([1, 3], augment=None)
    assert train.groups == ["a", "a"] and [test.sample(i).key for i in range(2)] == [1, 3]
    assert train.augment is not None and test.augment is None and data.augment is None
    test[0]
    assert 1 in data._cache  # loaded through the subset, cached for every view


def test_native_mask_is_at_the_frame_size():
    rgb, dhg, mask = frame(48, 64)
    data = FrameDataset([Sample(rgb, dhg, mask), Sample(rgb, dhg, None)], size=(12, 16))
    assert np.array_equal(data.native_mask(0), mask)
    assert data.native_mask(1).shape == (48, 64) and not data.native_mask(1).any()


def test_the_object_class_target_paints_instances_in_order_and_unknown_classes_are_background():
    rgb = np.zeros((8, 8, 3), np.uint8)
    cup, pan, bowl = (np.zeros((8, 8), bool) for _ in range(3))
    cup[0:4, 0:4] = True
    pan[2:6, 2:6] = True  # over the cup's corner: painted later, it wins there
    bowl[7, 7] = True
    sample = Sample(rgb=rgb, dhg=None, mask=cup | pan | bowl, instances=(("cup", cup), ("pan", pan), ("bowl", bowl)))
    data = FrameDataset([sample], size=(8, 8))
    assert data.class_names() == ["bowl", "cup", "pan"]
    target = data.with_classes(["pan", "cup"])[0]["mask"].numpy()
    expected = np.zeros((8, 8), np.int64)
    expected[0:4, 0:4] = 2
    expected[2:6, 2:6] = 1
    np.testing.assert_array_equal(target, expected)  # the bowl is no class of this list: background
    np.testing.assert_array_equal(data[0]["mask"].numpy(), (cup | pan | bowl).astype(np.int64))  # without classes: the mask
