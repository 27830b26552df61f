"""Depth for RGB-only frames: the scale-invariant loss, depth errors, assumed intrinsics, training and prediction.

GTEA Gaze+ and the children's dataset have no depth; the paper predicts it
with a monocular network (Liu et al. 2015) and makes DHG from the
prediction. ``fit_depth`` trains :class:`egonet.network.depth.DepthNet` on
frames with measured depth (Eigen et al. 2014's scale-invariant loss),
``DepthPredictor`` gives any RGB frame a depth map in metres, and
``egonet.dhg.dhg_from_depth`` turns it into DHG, with
:func:`assumed_intrinsics` when the camera is unknown.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch

from egonet import io
from egonet.checkpoint import CHECKPOINT_FORMAT, save_checkpoint
from egonet.data import resize_frame
from egonet.errors import EgonetError
from egonet.network.depth import DepthNet

__all__ = [
    "ASSUMED_HFOV_DEG", "DEPTH_MODEL", "DepthConfig", "DepthErrors", "DepthPredictor", "DepthSample",
    "assumed_intrinsics", "depth_errors", "fit_depth", "intrinsics_record", "scale_invariant_loss",
]

DEPTH_MODEL = "depth-lite"
"""The model name a depth run and its checkpoints carry."""

ASSUMED_HFOV_DEG = 60.0
"""Horizontal field of view assumed for a frame without intrinsics (a Kinect/PrimeSense is about 58-63 degrees)."""

MIN_DEPTH_M = 0.1
MAX_DEPTH_M = 10.0
"""Predictions are clipped to this range (the DHG encodes depth up to 10 m)."""


def scale_invariant_loss(log_pred: torch.Tensor, depth: torch.Tensor, *, lam: float = 0.5) -> torch.Tensor:
    """Eigen et al. (2014)'s scale-invariant log loss over the valid pixels.

    ``d = log_pred - log(depth)`` on pixels with ``depth > 0``; the loss is
    ``mean(d**2) - lam * mean(d)**2`` per image, averaged over the images
    that have a valid pixel. ``lam = 1`` ignores the global scale entirely,
    ``lam = 0`` is plain log-MSE; Eigen et al. train with 0.5.

    Args:
        log_pred: ``(N, 1, H, W)`` or ``(N, H, W)`` predicted log-depth (metres).
        depth: The same shape, measured depth in metres; 0 where missing.
        lam: The weight of the scale term, in ``[0, 1]``.

    Returns:
        A scalar tensor (0 when no image has a valid pixel).

    Example:
        >>> d = torch.tensor([[[1.0, 2.0]]])
        >>> float(scale_invariant_loss(torch.log(d * 2), d, lam=1.0))
        0.0
    """
    if log_pred.shape != depth.shape:
        raise EgonetError(f"log_pred {tuple(log_pred.shape)} and depth {tuple(depth.shape)} differ", field="depth")
    if not 0.0 <= lam <= 1.0:
        raise EgonetError(f"lam must be in [0, 1], got {lam}", field="lam")
    valid = (depth > 0).flatten(1).to(log_pred.dtype)
    d = (log_pred - torch.log(depth.clamp_min(1e-6))).flatten(1) * valid
    n = valid.sum(1)
    has = n > 0
    if not bool(has.any()):
        return log_pred.sum() * 0.0
    n = n[has]
    mean_sq = (d[has] ** 2).sum(1) / n
    mean = d[has].sum(1) / n
    return (mean_sq - lam * mean**2).mean()


@dataclass
class DepthErrors:
    """Sufficient statistics of depth errors over valid pixels; add them, then read the ratios.

    ``abs_rel`` is ``mean(|pred - gt| / gt)``; ``delta1`` the share of
    pixels with ``max(pred / gt, gt / pred) < 1.25`` (Eigen et al. 2014).
    """

    abs_rel_sum: float = 0.0
    delta1_hits: int = 0
    pixels: int = 0

    def __add__(self, other: DepthErrors) -> DepthErrors:
        return DepthErrors(self.abs_rel_sum + other.abs_rel_sum, self.delta1_hits + other.delta1_hits,
                           self.pixels + other.pixels)

    @property
    def abs_rel(self) -> float:
        return self.abs_rel_sum / self.pixels if self.pixels else math.nan

    @property
    def delta1(self) -> float:
        return self.delta1_hits / self.pixels if self.pixels else math.nan


def depth_errors(pred: np.ndarray, gt: np.ndarray, *, median_scaling: bool = False) -> DepthErrors:
    """One frame's depth error statistics over its pixels with ``gt > 0``.

    Args:
        pred: ``(H, W)`` predicted depth in metres (> 0).
        gt: ``(H, W)`` measured depth in metres; 0 or NaN where missing.
        median_scaling: Scale ``pred`` by ``median(gt) / median(pred)`` over
            the valid pixels first (the usual convention for monocular
            depth, which fixes the unknowable global scale); without it the
            metric scale counts too.

    Example:
        >>> e = depth_errors(np.array([[1.0, 3.0]]), np.array([[1.0, 2.0]]))
        >>> round(e.abs_rel, 3), e.delta1
        (0.25, 0.5)
    """
    pred, gt = np.asarray(pred, np.float64), np.nan_to_num(np.asarray(gt, np.float64), nan=0.0)
    if pred.shape != gt.shape or pred.ndim != 2:
        raise EgonetError(f"pred {pred.shape} and gt {gt.shape} must be the same (H, W)", field="pred")
    valid = gt > 0
    if not valid.any():
        return DepthErrors()
    p, g = pred[valid], gt[valid]
    if np.any(~np.isfinite(p)) or np.any(p <= 0):
        raise EgonetError("pred must be finite and > 0 where gt is valid", field="pred")
    if median_scaling:
        p = p * (np.median(g) / np.median(p))
    ratio = np.maximum(p / g, g / p)
    return DepthErrors(float(np.sum(np.abs(p - g) / g)), int(np.sum(ratio < 1.25)), int(valid.sum()))


def assumed_intrinsics(width: int, height: int, *, hfov_deg: float = ASSUMED_HFOV_DEG) -> np.ndarray:
    """A camera matrix for a frame whose camera is unknown: square pixels, centred, ``hfov_deg`` wide.

    ``fx = fy = (width / 2) / tan(hfov / 2)``, ``cx = (width - 1) / 2``,
    ``cy = (height - 1) / 2``.

    Example:
        >>> assumed_intrinsics(640, 480, hfov_deg=90.0)[0].round(1).tolist()
        [320.0, 0.0, 319.5]
    """
    if width < 1 or height < 1:
        raise EgonetError(f"width and height must be >= 1, got {width}x{height}", field="size")
    if not 1.0 <= hfov_deg <= 170.0:
        raise EgonetError(f"hfov_deg must be in [1, 170], got {hfov_deg}", field="hfov_deg")
    f = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def intrinsics_record(K: np.ndarray, *, hfov_deg: float = ASSUMED_HFOV_DEG) -> dict:
    """Assumed intrinsics as plain data (for a frame's record): the field of view and ``fx, fy, cx, cy``."""
    return {"hfov_deg": float(hfov_deg), "fx": round(float(K[0, 0]), 2), "fy": round(float(K[1, 1]), 2),
            "cx": float(K[0, 2]), "cy": float(K[1, 2])}


@dataclass(frozen=True)
class DepthSample:
    """A frame with measured depth: RGB and depth (paths or arrays), its key and its activity."""

    rgb: object
    depth: object
    key: object = None
    group: str = "frames"


@dataclass(frozen=True)
class DepthConfig:
    """A depth run's settings; every field is checked here.

    Attributes:
        epochs: Passes over the training frames.
        width, height: Training size (frames and depth are resized to it; depth with nearest neighbour).
        lr: Adam's learning rate.
        batch_size: Frames per step.
        seed: Seeds the weights, the order and the flips.
        test_fraction: The last share of each activity's frames held out for the errors.
        lam: The scale-invariant loss's weight of the scale term.
        net_width: The network's width (:class:`DepthNet`).
        device: ``"auto"``, ``"cpu"`` or ``"cuda"``.
    """

    epochs: int = 10
    width: int = 160
    height: int = 120
    lr: float = 1e-3
    batch_size: int = 4
    seed: int = 0
    test_fraction: float = 0.2
    lam: float = 0.5
    net_width: int = 128
    device: str = "auto"

    def __post_init__(self) -> None:
        for name, low in (("epochs", 1), ("batch_size", 1), ("seed", 0), ("net_width", 8)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise EgonetError(f"{name} must be an integer >= {low}, got {value!r}", field=name)
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 16 <= value <= 4096:
                raise EgonetError(f"{name} must be an integer in 16..4096, got {value!r}", field=name)
        if not (isinstance(self.lr, int | float) and 0 < self.lr < 1):
            raise EgonetError(f"lr must be in (0, 1), got {self.lr!r}", field="lr")
        if not 0 < self.test_fraction < 1:
            raise EgonetError(f"test_fraction must be in (0, 1), got {self.test_fraction!r}", field="test_fraction")
        if not 0 <= self.lam <= 1:
            raise EgonetError(f"lam must be in [0, 1], got {self.lam!r}", field="lam")
        if self.device not in ("auto", "cpu", "cuda"):
            raise EgonetError(f"device must be one of auto, cpu, cuda, got {self.device!r}", field="device")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping) -> DepthConfig:
        return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})


@dataclass
class DepthResult:
    """What ``fit_depth`` returns: the held-out errors, the constant baseline's, the history and the checkpoint."""

    metrics: dict
    history: list[dict] = field(default_factory=list)
    train_keys: list = field(default_factory=list)
    test_keys: list = field(default_factory=list)
    checkpoint: Path | None = None


def _load(sample: DepthSample, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    rgb = sample.rgb if isinstance(sample.rgb, np.ndarray) else io.read_image(sample.rgb)
    depth = sample.depth if isinstance(sample.depth, np.ndarray) else io.read_depth(sample.depth)
    if rgb.shape[:2] != depth.shape:
        raise EgonetError(f"frame {sample.key}: RGB {rgb.shape[:2]} and depth {depth.shape} differ in size", field="depth")
    depth = np.nan_to_num(depth.astype(np.float32), nan=0.0)
    # Nearest neighbour keeps missing pixels missing (no blend of 0 and a real depth).
    small = cv2.resize(depth, (size[1], size[0]), interpolation=cv2.INTER_NEAREST)
    return resize_frame(rgb, size), small


def _split(samples: Sequence[DepthSample], test_fraction: float) -> tuple[list[int], list[int]]:
    """The last ``ceil(test_fraction * n)`` frames of each activity with ``n >= 2`` are held out (as ``make_folds`` single)."""
    from egonet.train import make_folds

    fold = make_folds([s.group for s in samples], mode="single", test_fraction=test_fraction)[0]
    return fold.train, fold.test


def _errors(net: DepthNet, frames: list[tuple[np.ndarray, np.ndarray]], device: torch.device, *,
            constant: float, lam: float) -> dict:
    """Held-out loss and errors of the network, with and without median scaling, and of the constant depth."""
    raw, scaled, base, losses = DepthErrors(), DepthErrors(), DepthErrors(), []
    net.eval()
    with torch.no_grad():
        for rgb, gt in frames:
            log_pred = net(_tensor(rgb[None], device))[0, 0]
            losses.append(float(scale_invariant_loss(log_pred[None], torch.from_numpy(gt)[None].to(device), lam=lam)))
            pred = np.clip(np.exp(log_pred.cpu().numpy()), MIN_DEPTH_M, MAX_DEPTH_M)
            raw += depth_errors(pred, gt)
            scaled += depth_errors(pred, gt, median_scaling=True)
            base += depth_errors(np.full_like(gt, constant), gt)
    return {
        "loss": float(np.mean(losses)) if losses else None,
        "abs_rel": raw.abs_rel, "delta1": raw.delta1,
        "abs_rel_median_scaled": scaled.abs_rel, "delta1_median_scaled": scaled.delta1,
        "constant_abs_rel": base.abs_rel, "constant_delta1": base.delta1,
        "constant_depth_m": constant, "pixels": raw.pixels,
    }


def _tensor(rgb: np.ndarray, device: torch.device) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(rgb)).permute(0, 3, 1, 2).float().to(device)


def fit_depth(
    samples: Sequence[DepthSample],
    config: DepthConfig,
    *,
    out_path: Path | None = None,
    on_epoch: Callable[[dict], None] | None = None,
    on_progress: Callable | None = None,
) -> DepthResult:
    """Train a depth network on frames with measured depth; score it on held-out ones against a constant depth.

    The last ``config.test_fraction`` of each activity's frames are held
    out (a contiguous block, so neighbouring video frames stay on one side).
    Adam minimises :func:`scale_invariant_loss` on the training frames, each
    drawn left-right flipped half the time. After every epoch the held-out
    frames give the loss, AbsRel and delta<1.25 (raw and median-scaled);
    the baseline predicts the training frames' median depth everywhere.

    Args:
        samples: Frames with measured depth (at least two in one activity).
        config: The settings.
        out_path: Where the checkpoint goes (``egonet.checkpoint`` format, model ``"depth-lite"``).
        on_epoch: Called with each epoch's record.
        on_progress: Called with an ``egonet.train.Progress`` after every step (it may raise to stop).

    Returns:
        The final held-out metrics (plus the baseline's), the history, and the keys of both sides.

    Raises:
        EgonetError: Too few frames, or a frame whose depth and RGB differ in size.
    """
    from egonet.train import Progress, resolve_device

    if len(samples) < 2:
        raise EgonetError(f"depth training needs at least two frames with measured depth, got {len(samples)}",
                          field="frames")
    device = resolve_device(config.device)
    train_ids, test_ids = _split(samples, config.test_fraction)
    size = (config.height, config.width)
    train = [_load(samples[i], size) for i in train_ids]
    test = [_load(samples[i], size) for i in test_ids]
    valid = np.concatenate([d[d > 0] for _, d in train])
    if valid.size == 0:
        raise EgonetError("the training frames have no valid depth pixel", field="frames")
    constant = float(np.median(valid))
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    net = DepthNet(width=config.net_width).to(device)
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr)
    steps_per_epoch = math.ceil(len(train) / config.batch_size)
    steps, step, started = steps_per_epoch * config.epochs, 0, time.monotonic()
    history: list[dict] = []
    for epoch in range(1, config.epochs + 1):
        net.train()
        order = rng.permutation(len(train))
        total = 0.0
        for first in range(0, len(order), config.batch_size):
            batch = [train[i] for i in order[first:first + config.batch_size]]
            flips = rng.random(len(batch)) < 0.5
            rgb = np.stack([r[:, ::-1] if f else r for (r, _), f in zip(batch, flips, strict=True)])
            gt = np.stack([d[:, ::-1] if f else d for (_, d), f in zip(batch, flips, strict=True)])
            loss = scale_invariant_loss(net(_tensor(rgb, device)), torch.from_numpy(np.ascontiguousarray(gt))[:, None].to(device),
                                        lam=config.lam)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item() * len(batch)
            step += 1
            if on_progress is not None:
                elapsed = time.monotonic() - started
                on_progress(Progress(fold="depth", fold_index=0, folds=1, epoch=epoch, epochs=config.epochs, step=step,
                                     steps=steps, loss=total / min(first + len(batch), len(order)),
                                     eta_s=elapsed / step * (steps - step), phase="train"))
        record = {"epoch": epoch, "lr": config.lr, "train_loss": total / len(train)}
        record |= _errors(net, test, device, constant=constant, lam=config.lam)
        history.append(record)
        if on_epoch is not None:
            on_epoch(record)
    metrics = dict(history[-1]) | {"epochs": config.epochs, "test_frames": len(test), "train_frames": len(train)}
    train_keys, test_keys = [samples[i].key for i in train_ids], [samples[i].key for i in test_ids]
    if out_path is not None:
        save_checkpoint(out_path, {
            "format": CHECKPOINT_FORMAT,
            "model": {"name": DEPTH_MODEL, "options": {"width": config.net_width}},
            "state_dict": {k: v.cpu() for k, v in net.state_dict().items()},
            "config": config.to_dict(),
            "fold": "depth",
            "train_keys": list(train_keys),
            "test_keys": list(test_keys),
            "epoch": config.epochs,
            "complete": True,
            "metrics": metrics,
            "history": history,
        })
    return DepthResult(metrics, history, train_keys, test_keys, out_path)


class DepthPredictor:
    """A trained depth network: RGB in, depth in metres out, at the frame's own size.

    Args:
        state: A checkpoint of ``fit_depth`` (``egonet.checkpoint.load_checkpoint``).
        device: Where the network runs.

    Raises:
        EgonetError: If the checkpoint is not a depth model's.
    """

    def __init__(self, state: Mapping, *, device: str | torch.device = "cpu") -> None:
        model = state.get("model") or {}
        if model.get("name") != DEPTH_MODEL:
            raise EgonetError(f"not a depth checkpoint (its model is {model.get('name')!r}, not {DEPTH_MODEL!r})",
                              field="checkpoint")
        self.config = DepthConfig.from_dict(state["config"])
        self.device = torch.device(device)
        self.net = DepthNet(width=int(model["options"]["width"]))
        self.net.load_state_dict(state["state_dict"])
        self.net.to(self.device).eval()

    def predict(self, rgb: np.ndarray) -> np.ndarray:
        """``(H, W, 3)`` uint8 RGB -> ``(H, W)`` float32 depth in metres, clipped to 0.1..10 m."""
        height, width = io.check_rgb(rgb, "rgb")
        small = resize_frame(np.asarray(rgb), (self.config.height, self.config.width))
        with torch.no_grad():
            log_depth = self.net(_tensor(small[None], self.device))[0, 0].cpu().numpy()
        depth = np.exp(resize_frame(log_depth.astype(np.float32), (height, width)))
        return np.clip(depth, MIN_DEPTH_M, MAX_DEPTH_M).astype(np.float32)
