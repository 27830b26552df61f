"""Training data: frames (RGB, DHG, mask) at a fixed training size, with paired augmentation.

A :class:`Sample` names one labelled frame by arrays or by file paths (read
with :mod:`egonet.io`); a :class:`FrameDataset` turns samples into tensors the
networks take::

    >>> import numpy as np
    >>> rgb = np.zeros((48, 64, 3), np.uint8); dhg = rgb.copy(); mask = np.zeros((48, 64), bool)
    >>> data = FrameDataset([Sample(rgb=rgb, dhg=dhg, mask=mask, group="cooking")], size=(24, 32))
    >>> item = data[0]
    >>> item["rgb"].shape, item["mask"].shape, item["mask"].dtype
    (torch.Size([3, 24, 32]), torch.Size([24, 32]), torch.int64)

Every frame is first resized to the training size ``(H, W)`` (area
interpolation when shrinking, bilinear when enlarging; the mask with nearest
neighbour) and kept in a cache shared by the subsets of one dataset. With an
:class:`Augment`, one geometric transform (a zoom by ``s >= 1`` around a
random point, i.e. a random crop rescaled to the training size, and a
horizontal flip) is drawn per item and applied to RGB, DHG and mask alike
(the mask with nearest neighbour, so it stays binary); brightness, contrast
and saturation changes touch RGB only, because DHG channels are
measurements, not appearance. Zooming in only (``s >= 1``) keeps every output
pixel inside the frame, so no padding and no "ignore" label are needed.

Flips are horizontal only: first-person frames keep the ground at the bottom
and the hands below the centre, which the coordinate embedding learns; a
left-right mirror is still a plausible frame (left- and right-handed
actions), an upside-down one is not.

Augmentations are drawn from ``numpy.random.default_rng([seed, epoch,
index])``: the same seed, epoch and item give the same transform whatever
process or worker loads it, which is what makes resumed and distributed
training repeat exactly. Call :meth:`FrameDataset.set_epoch` at the start of
every epoch.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset

from egonet import io
from egonet.errors import EgonetError
from egonet.io import check_rgb

__all__ = ["Augment", "FrameDataset", "Sample", "check_size", "load_sample", "resize_frame", "resize_probability"]

MIN_SIDE = 8

Source = np.ndarray | str | Path


@dataclass(frozen=True)
class Sample:
    """One labelled frame.

    Attributes:
        rgb: uint8 ``(H, W, 3)`` RGB, or the path of a JPEG/PNG file.
        dhg: uint8 ``(H, W, 3)`` DHG (gray, height, depth), or the path of its
            PNG; ``None`` for models that do not read DHG (zeros are given).
        mask: bool ``(H, W)`` action-object mask, or the path of a mask PNG;
            ``None`` means the frame has no action-object (all false).
        group: The frame's activity; leave-one-activity-out splits on it.
        key: The caller's name for the frame (a database id, a file name).
        instances: The labelled objects as ``(class name, mask)`` pairs, each
            mask a bool ``(H, W)`` array or a PNG's path, painted in order
            (a later one wins where two overlap): the targets of object-class
            segmentation (DeepLab-Obj, :meth:`FrameDataset.with_classes`).
    """

    rgb: Source
    dhg: Source | None
    mask: Source | None
    group: str = ""
    key: int | str | None = None
    instances: tuple[tuple[str, Source], ...] = ()


@dataclass(frozen=True)
class Augment:
    """Random paired augmentation (see the module docstring).

    Attributes:
        max_zoom: Largest zoom factor ``s`` (drawn uniformly in ``[1, max_zoom]``);
            1 disables cropping.
        flip: Mirror left-right with probability 1/2.
        brightness: RGB is multiplied by a factor in ``[1 - b, 1 + b]``.
        contrast: RGB is pulled towards (or pushed from) its mean gray by a
            factor in ``[1 - c, 1 + c]``.
        saturation: RGB is blended with its gray image by a factor in
            ``[1 - s, 1 + s]``.
    """

    max_zoom: float = 1.25
    flip: bool = True
    brightness: float = 0.2
    contrast: float = 0.2
    saturation: float = 0.2

    def __post_init__(self) -> None:
        if not (isinstance(self.max_zoom, int | float) and 1.0 <= self.max_zoom <= 4.0):
            raise EgonetError(f"max_zoom must be a number in [1, 4], got {self.max_zoom!r}", field="max_zoom")
        for name in ("brightness", "contrast", "saturation"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and 0.0 <= value < 1.0):
                raise EgonetError(f"{name} must be a number in [0, 1), got {value!r}", field=name)


def load_sample(sample: Sample) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Read a sample's RGB, DHG and mask at the frame's own size, checked.

    Returns:
        ``(rgb uint8 (H, W, 3), dhg uint8 (H, W, 3) or None, mask bool (H, W))``.

    Raises:
        ValueError: If an array has the wrong dtype or shape, or the three
            sizes differ (the message names the sample's key).
        egonet.io.MediaError: If a file cannot be read.
    """
    name = f"sample {sample.key!r}" if sample.key is not None else "sample"
    rgb = _read(sample.rgb, io.read_image)
    check_rgb(rgb, f"{name}: rgb", min_side=MIN_SIDE)
    height, width = rgb.shape[:2]
    dhg = None if sample.dhg is None else _read(sample.dhg, io.read_dhg)
    if dhg is not None:
        check_rgb(dhg, f"{name}: dhg", min_side=MIN_SIDE)
        if dhg.shape != rgb.shape:
            raise EgonetError(f"{name}: dhg is {dhg.shape[1]}x{dhg.shape[0]}, the RGB frame {width}x{height}", field="dhg")
    if sample.mask is None:
        mask = np.zeros((height, width), bool)
    else:
        mask = _read(sample.mask, io.read_mask)
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.ndim != 2:
            raise EgonetError(f"{name}: mask must be a bool (H, W) array, got {_describe(mask)}", field="mask")
        if mask.shape != (height, width):
            raise EgonetError(f"{name}: mask is {mask.shape[1]}x{mask.shape[0]}, the RGB frame {width}x{height}", field="mask")
    return rgb, dhg, mask


def resize_frame(image: np.ndarray, size: tuple[int, int], *, nearest: bool = False) -> np.ndarray:
    """Resize an image or mask to ``size = (H, W)``.

    Area interpolation when shrinking (no aliasing), bilinear when enlarging,
    nearest neighbour for masks (``nearest=True``; bool stays bool).
    """
    height, width = size
    if image.shape[:2] == (height, width):
        return image
    if nearest:
        out = cv2.resize(image.astype(np.uint8), (width, height), interpolation=cv2.INTER_NEAREST)
        return out.astype(image.dtype)
    shrink = height * width < image.shape[0] * image.shape[1]
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def resize_probability(probability: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A probability map at the training size back to a frame's ``shape = (H, W)``.

    Bilinear, clipped to ``[0, 1]``, float32. The held-out maps of training
    and every prediction go through here, so the two agree.
    """
    if probability.shape != tuple(shape):
        probability = cv2.resize(probability, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)
    return np.clip(probability, 0.0, 1.0).astype(np.float32, copy=False)


class FrameDataset(Dataset):
    """Samples at a fixed training size, optionally augmented.

    Items are dicts of ``rgb`` and ``dhg`` float32 ``(3, H, W)`` in ``[0, 1]``,
    ``mask`` int64 ``(H, W)`` (0 background, 1 action-object; with
    :meth:`with_classes`, 0 background and ``k`` the ``k``-th class's
    instances) and ``index`` (the item's position in this dataset).

    Args:
        samples: The frames.
        size: Training size ``(H, W)``, each side >= 8.
        augment: Random augmentation for training, ``None`` for evaluation.
        seed: Seed of the augmentation draws.
        cache: Keep each frame at the training size in memory after its first
            read (about ``7 * H * W`` bytes a frame), shared with subsets.

    Raises:
        EgonetError: If ``samples`` is empty or ``size`` is invalid.
    """

    def __init__(
        self,
        samples: Sequence[Sample],
        *,
        size: tuple[int, int],
        augment: Augment | None = None,
        seed: int = 0,
        cache: bool = True,
    ) -> None:
        samples = list(samples)
        if not samples:
            raise EgonetError("samples is empty: give at least one labelled frame", field="samples")
        for i, sample in enumerate(samples):
            if not isinstance(sample, Sample):
                raise EgonetError(
                    f"samples[{i}] must be an egonet.data.Sample, got {type(sample).__name__}", field=f"samples[{i}]"
                )
        self.samples = samples
        self.size = check_size(size)
        self.augment = augment
        self.seed = int(seed)
        self.epoch = 0
        self._cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = {} if cache else None
        self._instance_cache: dict[int, np.ndarray] | None = {} if cache else None
        self._positions = list(range(len(samples)))  # positions in the shared cache
        self.classes: tuple[str, ...] | None = None

    def __len__(self) -> int:
        return len(self._positions)

    @property
    def groups(self) -> list[str]:
        """The group (activity) of every item, in order."""
        return [self.samples[p].group for p in self._positions]

    def sample(self, index: int) -> Sample:
        return self.samples[self._positions[index]]

    def subset(self, indices: Sequence[int], *, augment: Augment | None) -> FrameDataset:
        """The items at ``indices``, sharing this dataset's cache, with their own augmentation."""
        out = copy.copy(self)  # shallow: the samples list and the cache dict are shared
        out._positions = [self._positions[i] for i in indices]
        out.augment = augment
        return out

    def class_names(self) -> list[str]:
        """The class names of every item's instances, sorted (each once)."""
        return sorted({name for i in range(len(self)) for name, _ in self.sample(i).instances})

    def with_classes(self, classes: Sequence[str]) -> FrameDataset:
        """The same items whose ``mask`` is the object-class map: 0 background, ``k`` an instance of ``classes[k - 1]``.

        An instance of a class not in ``classes`` (one only held-out frames
        have) is background.
        """
        out = copy.copy(self)
        out.classes = tuple(classes)
        return out

    def set_epoch(self, epoch: int) -> None:
        """Choose the epoch whose augmentation draws the next items use."""
        self.epoch = int(epoch)

    def base(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(rgb, dhg, mask)`` of item ``index`` at the training size, not augmented."""
        position = self._positions[index]
        if self._cache is not None and position in self._cache:
            return self._cache[position]
        rgb, dhg, mask = load_sample(self.samples[position])
        rgb = resize_frame(rgb, self.size)
        dhg = np.zeros_like(rgb) if dhg is None else resize_frame(dhg, self.size)
        mask = resize_frame(mask, self.size, nearest=True)
        if self._cache is not None:
            self._cache[position] = (rgb, dhg, mask)
        return rgb, dhg, mask

    def native(self, index: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """``(rgb, dhg, mask)`` of item ``index`` at the frame's own size (read again, not cached)."""
        return load_sample(self.sample(index))

    def native_mask(self, index: int) -> np.ndarray:
        """The mask of item ``index`` at the frame's own size, bool ``(H, W)`` (read again, not cached)."""
        sample = self.sample(index)
        if sample.mask is not None:
            mask = _read(sample.mask, io.read_mask)
            if isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.ndim == 2:
                return mask
        return load_sample(sample)[2]  # no mask (all false at the frame's size), or one to check

    def instance_map(self, index: int) -> np.ndarray:
        """uint8 ``(H, W)`` at the training size: 0 nowhere, ``i + 1`` where instance ``i`` of the sample is painted."""
        position = self._positions[index]
        if self._instance_cache is not None and position in self._instance_cache:
            return self._instance_cache[position]
        sample = self.samples[position]
        if len(sample.instances) > 255:
            raise EgonetError(f"sample {sample.key!r}: at most 255 instances, got {len(sample.instances)}", field="instances")
        shape = self.base(index)[2].shape
        out = np.zeros(shape, np.uint8)
        for i, (_, source) in enumerate(sample.instances):
            mask = _read(source, io.read_mask)
            if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.ndim != 2:
                raise EgonetError(f"sample {sample.key!r}: instances[{i}] must be a bool (H, W) mask, got {_describe(mask)}",
                                  field="instances")  # fmt: skip
            out[resize_frame(mask, shape, nearest=True)] = i + 1
        if self._instance_cache is not None:
            self._instance_cache[position] = out
        return out

    def target(self, index: int) -> np.ndarray:
        """Item ``index``'s target at the training size: the bool mask, or with classes the uint8 class map."""
        mask = self.base(index)[2]
        if self.classes is None:
            return mask
        number = {name: k + 1 for k, name in enumerate(self.classes)}
        lut = np.array([0] + [number.get(name, 0) for name, _ in self.sample(index).instances], np.uint8)
        return lut[self.instance_map(index)]

    def __getitem__(self, index: int) -> dict[str, torch.Tensor | int]:
        rgb, dhg, _ = self.base(index)
        mask = self.target(index)
        if self.augment is not None:
            rng = np.random.default_rng([self.seed, self.epoch, self._positions[index]])
            rgb, dhg, mask = augment_frame(rgb, dhg, mask, self.augment, rng)
        return {
            "rgb": _to_tensor(rgb),
            "dhg": _to_tensor(dhg),
            "mask": torch.from_numpy(mask.astype(np.int64)),
            "index": index,
        }


def augment_frame(
    rgb: np.ndarray, dhg: np.ndarray, mask: np.ndarray, augment: Augment, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Apply one random geometric transform to all three, then photometric changes to RGB.

    Args:
        rgb: uint8 ``(H, W, 3)``.
        dhg: uint8 ``(H, W, 3)``.
        mask: bool or uint8 (class map) ``(H, W)``.
        augment: What to draw.
        rng: The draws' source.

    Returns:
        ``(rgb, dhg, mask)`` of the same sizes and dtypes.
    """
    height, width = mask.shape
    zoom = rng.uniform(1.0, augment.max_zoom)
    flip = augment.flip and rng.random() < 0.5
    # Output pixel (u, v) reads input pixel (a u + tx, a v + ty) with a = 1 / zoom;
    # the offsets keep the sampled window inside the frame. Mirroring reads column W-1-u.
    a = 1.0 / zoom
    tx = rng.uniform(0.0, (width - 1) * (1.0 - a))
    ty = rng.uniform(0.0, (height - 1) * (1.0 - a))
    sx = -a if flip else a
    x0 = tx + (width - 1) * a if flip else tx
    matrix = np.array([[sx, 0.0, x0], [0.0, a, ty]])
    flags = cv2.WARP_INVERSE_MAP
    warp = {"dsize": (width, height), "borderMode": cv2.BORDER_REFLECT_101}
    rgb = cv2.warpAffine(rgb, matrix, flags=flags | cv2.INTER_LINEAR, **warp)
    dhg = cv2.warpAffine(dhg, matrix, flags=flags | cv2.INTER_LINEAR, **warp)
    mask = cv2.warpAffine(mask.astype(np.uint8), matrix, flags=flags | cv2.INTER_NEAREST, **warp).astype(mask.dtype)
    rgb = _photometric(rgb, augment, rng)
    return rgb, dhg, mask


def _photometric(rgb: np.ndarray, augment: Augment, rng: np.random.Generator) -> np.ndarray:
    x = rgb.astype(np.float32)
    x *= rng.uniform(1.0 - augment.brightness, 1.0 + augment.brightness)
    gray = x @ np.array([0.299, 0.587, 0.114], np.float32)
    x = gray.mean() + (x - gray.mean()) * rng.uniform(1.0 - augment.contrast, 1.0 + augment.contrast)
    gray = x @ np.array([0.299, 0.587, 0.114], np.float32)
    x = gray[..., None] + (x - gray[..., None]) * rng.uniform(1.0 - augment.saturation, 1.0 + augment.saturation)
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def _to_tensor(image: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1))).float().div_(255.0)


def _read(source: object, reader) -> object:
    if isinstance(source, str | Path):
        return reader(source)
    return source


def check_size(size: object) -> tuple[int, int]:
    """``size`` as ``(height, width)`` ints, each >= 8.

    Raises:
        EgonetError: naming ``size``.
    """
    if (
        not isinstance(size, tuple | list)
        or len(size) != 2
        or any(isinstance(s, bool) or not isinstance(s, int | np.integer) or s < MIN_SIDE for s in size)
    ):
        raise EgonetError(f"size must be (height, width) with integers >= {MIN_SIDE}, got {size!r}", field="size")
    return int(size[0]), int(size[1])


def _describe(value: object) -> str:
    if isinstance(value, np.ndarray):
        return f"{value.dtype} {value.shape}"
    return type(value).__name__

