"""The training engine: per-pixel cross-entropy, SGD, leave-one-activity-out.

Short and linear on purpose (after nanoGPT): :func:`train_one_epoch` runs
the optimiser over a loader, :func:`evaluate` scores held-out frames (MF and
AP, and the action-object prior beside them), :func:`fit` trains one fold
with checkpoints, and :func:`cross_validate` is the outer loop, one model per
held-out activity (``folds="loao"``), one model on a single split, or one
model on every frame, none held out (``folds="all"``: scored elsewhere)::

    >>> from egonet.checkpoint import TrainConfig
    >>> from egonet.train import cross_validate
    >>> results = cross_validate(samples, TrainConfig(epochs=2), out_dir="runs/1")  # doctest: +SKIP
    >>> results[0].metrics["max_f"], results[0].metrics["aop_max_f"]  # doctest: +SKIP

What the paper fixes and what we chose (``shared/docs/egonet-reference.md``):

* Loss: per-pixel two-class softmax cross-entropy, as the paper; we average
  it over pixels and frames (``reduction="mean"``), where Caffe summed it.
* SGD, momentum 0.9, weight decay 5e-4, as the paper. The learning rate
  needs converting: the paper's 1e-6 multiplied an *unnormalised* loss, a
  sum over about 481 x 641 pixels x 15 frames = 4.6 M terms. For SGD,
  multiplying the loss by k is multiplying the learning rate by k, so the
  paper's step on a mean loss is lr = 1e-6 x 4.6e6 = 4.6 (or 0.31 if Caffe
  divided by the batch size, as ``normalize: false`` does). Those steps were
  taken from ImageNet DeepLab weights, with the weight decay in effect k
  times weaker (Caffe adds ``wd * w`` to the summed gradient). From a random
  initialisation (the only one offline for the VGG streams) such steps
  break training (on the demo, 4.6 collapses egonet-lite to a constant map
  and 0.31 learns far slower than 0.02), so each model gets its own default
  (:data:`egonet.checkpoint.DEFAULT_LR`): 0.02 for egonet-lite, whose batch normalisation
  tolerates larger steps (0.02 and 0.05 did alike on the demo), and 1e-3
  for the 138 M parameter VGG models, which have none. ``lr`` overrides it.
* Schedule (*choice*): DeepLab's "poly", ``lr * (1 - i / N) ** 0.9`` over the
  ``N`` planned iterations of the fold (``lr_power = 0`` keeps it constant).
* Seeds: the model of every fold starts from ``torch.manual_seed(seed)``;
  shuffling draws from ``(seed, epoch)`` and augmentation from ``(seed, epoch,
  frame)``, so a run repeats exactly, and a resumed run continues as if it
  had never stopped (the torch RNG state is in the checkpoint).
* Devices: ``device="auto"`` takes CUDA when available, else the CPU. When
  launched by ``torchrun`` (``WORLD_SIZE`` > 1), each process trains on its
  share of every batch (DistributedSampler) and DistributedDataParallel
  averages the gradients; only rank 0 evaluates, writes files and reports
  progress.

:func:`cross_validate` writes a checkpoint (``egonet.checkpoint``) per fold in
``out_dir`` after every epoch, with ``config.json`` (the resolved config)
beside them, and resumes a fold from its file when it exists; beside the
format's keys it holds the optimiser and RNG state.
"""

from __future__ import annotations

import json
import math
import os
import re
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader, DistributedSampler

from egonet.baselines import ActionObjectPrior
from egonet.checkpoint import DEVICES, FOLD_MODES, TrainConfig, checkpoint_state, load_checkpoint, save_checkpoint
from egonet.data import FrameDataset, Sample, resize_probability
from egonet.errors import EgonetError
from egonet.init import initialise
from egonet.metrics import ScoreAccumulator
from egonet.network.builders import build_model, learns_classes, saved_options
from egonet.network.model import EgoNetModel, action_object_probability

__all__ = [
    "Fold",
    "FoldResult",
    "Progress",
    "cross_validate",
    "evaluate",
    "fit",
    "make_folds",
    "resolve_device",
    "train_one_epoch",
]


# --------------------------------------------------------------------------- folds


@dataclass(frozen=True)
class Fold:
    """One train/test split: positions in the sample list.

    Attributes:
        name: The held-out activity, ``"single"`` or ``"all"``.
        train: Positions of the training samples.
        test: Positions of the held-out samples (none for ``"all"``).
    """

    name: str
    train: list[int]
    test: list[int]


def make_folds(groups: Sequence[str], *, mode: str, test_fraction: float = 0.2) -> list[Fold]:
    """Leave-one-activity-out folds, or one split.

    Args:
        groups: The activity of every sample, in order.
        mode: ``"loao"``: one fold per activity (in order of first
            appearance), testing on it and training on the others.
            ``"single"``: one fold, ``"single"``, testing on the last
            ``ceil(test_fraction * n)`` samples of each activity with ``n >= 2``.
            ``"all"``: one fold, ``"all"``, training on every sample and
            holding none out (a model for other datasets or activities).
        test_fraction: See ``mode``.

    Raises:
        EgonetError: If a split would leave no training or no test frame
            (fewer than two activities for ``"loao"``).

    Example:
        >>> [(f.name, f.test) for f in make_folds(["a", "a", "b"], mode="loao")]
        [('a', [0, 1]), ('b', [2])]
    """
    if mode not in FOLD_MODES:
        raise EgonetError(f"mode must be one of {', '.join(FOLD_MODES)}, got {mode!r}", field="mode")
    by_group: dict[str, list[int]] = {}
    for i, group in enumerate(groups):
        by_group.setdefault(group, []).append(i)
    if mode == "loao":
        if len(by_group) < 2:
            raise EgonetError(
                f"leave-one-activity-out needs frames from at least two activities, got {len(by_group)}: "
                "label more activities or use a single split",
                field="groups",
            )
        return [
            Fold(name, [i for g, ids in by_group.items() if g != name for i in ids], list(test))
            for name, test in by_group.items()
        ]
    if mode == "all":
        if not groups:
            raise EgonetError("training on every frame needs at least one labelled frame", field="groups")
        return [Fold("all", list(range(len(groups))), [])]
    train, test = [], []
    for ids in by_group.values():
        n_test = math.ceil(test_fraction * len(ids)) if len(ids) >= 2 else 0
        train += ids[: len(ids) - n_test]
        test += ids[len(ids) - n_test :]
    if not test:
        raise EgonetError("a single split needs an activity with at least two labelled frames", field="groups")
    return [Fold("single", train, test)]


# --------------------------------------------------------------------------- devices


def resolve_device(device: str) -> torch.device:
    """``"auto"`` -> CUDA when available, else CPU; under torchrun, this process's GPU.

    Raises:
        EgonetError: If ``device`` is unknown, or ``"cuda"`` without a usable GPU.
    """
    if device not in DEVICES:
        raise EgonetError(f"device must be one of {', '.join(DEVICES)}, got {device!r}", field="device")
    if device == "cuda" and not torch.cuda.is_available():
        raise EgonetError(
            "device 'cuda' was asked for but torch sees no CUDA GPU: use --device cpu or auto", field="device"
        )
    if device == "cpu" or not torch.cuda.is_available():
        return torch.device("cpu")
    return torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))


def world() -> tuple[int, int]:
    """``(rank, world_size)`` of this process (``(0, 1)`` unless launched by torchrun)."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def setup_distributed(device: torch.device) -> tuple[int, int]:
    """Join the torchrun process group when ``WORLD_SIZE`` > 1 (once); return ``(rank, world_size)``."""
    if int(os.environ.get("WORLD_SIZE", "1")) > 1 and not dist.is_initialized():
        if device.type == "cuda":
            torch.cuda.set_device(device)
        dist.init_process_group(backend="nccl" if device.type == "cuda" else "gloo")
    return world()


def _barrier() -> None:
    if world()[1] > 1:
        dist.barrier()


# --------------------------------------------------------------------------- progress


@dataclass(frozen=True)
class Progress:
    """What a progress callback receives (rank 0 only).

    Attributes:
        fold: The fold being trained.
        fold_index: Its position (0-based) among ``folds``.
        folds: Number of folds in the run.
        epoch: The epoch under way (1-based; 0 before the first).
        epochs: Epochs per fold.
        step: Optimiser steps done in the whole run (resumed ones included).
        steps: Steps the whole run takes.
        loss: Mean training loss of the epoch so far (``None`` before a step).
        eta_s: Seconds left, from the pace of the steps run in this process.
        phase: ``"train"``, ``"evaluate"`` or ``"done"``.
    """

    fold: str
    fold_index: int
    folds: int
    epoch: int
    epochs: int
    step: int
    steps: int
    loss: float | None
    eta_s: float | None
    phase: str

    @property
    def fraction(self) -> float:
        return self.step / self.steps if self.steps else 1.0


class _Tracker:
    """Counts steps over all folds and reports to the callback (rank 0)."""

    def __init__(self, *, steps: int, folds: int, epochs: int, callback: Callable[[Progress], None] | None):
        self.steps, self.folds, self.epochs, self.callback = steps, folds, epochs, callback
        self.step = 0
        self.timed_steps = 0
        self.started: float | None = None
        self.state = {"fold": "", "fold_index": 0, "epoch": 0, "loss": None, "phase": "train"}

    def skip(self, steps: int) -> None:
        """Count steps done before (a resumed checkpoint) without timing them."""
        self.step += steps

    def update(self, *, steps: int = 0, **state) -> None:
        if steps:
            # The pace is measured from the end of the first step: loading and warm-up are not steps.
            if self.started is None:
                self.started = time.monotonic()
            else:
                self.timed_steps += steps
            self.step += steps
        self.state.update(state)
        if self.callback is None or world()[0] != 0:
            return
        eta = None
        if self.timed_steps:
            eta = (time.monotonic() - self.started) / self.timed_steps * (self.steps - self.step)
        self.callback(
            Progress(folds=self.folds, epochs=self.epochs, step=self.step, steps=self.steps, eta_s=eta, **self.state)
        )


# --------------------------------------------------------------------------- engine


def train_one_epoch(
    model: torch.nn.Module,
    loader: DataLoader,
    optimizer: torch.optim.Optimizer,
    *,
    device: torch.device,
    lr_at: Callable[[int], float],
    iteration: int,
    amp: bool = True,
    on_step: Callable[[float], None] | None = None,
) -> tuple[float, int]:
    """One pass over ``loader``.

    Args:
        model: The model (or its DistributedDataParallel wrapper), in train mode.
        loader: Batches of :class:`~egonet.data.FrameDataset` items.
        optimizer: The SGD optimiser.
        device: Where the model is.
        lr_at: The learning rate of an iteration (the schedule).
        iteration: Iterations done before this epoch.
        amp: bfloat16 autocast on CUDA.
        on_step: Called after each step with the running mean loss.

    Returns:
        ``(mean loss over the epoch's frames, iterations done after it)``.
    """
    model.train()
    total, frames = 0.0, 0
    autocast = amp and device.type == "cuda"
    for batch in loader:
        for group in optimizer.param_groups:
            group["lr"] = lr_at(iteration)
        rgb = batch["rgb"].to(device, non_blocking=True)
        dhg = batch["dhg"].to(device, non_blocking=True)
        target = batch["mask"].to(device, non_blocking=True)
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=autocast):
            logits = model(rgb, dhg)
        # The mean over pixels and frames; see the module docstring for the lr conversion.
        loss = F.cross_entropy(logits.float(), target)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        iteration += 1
        total += loss.item() * len(target)
        frames += len(target)
        if on_step is not None:
            on_step(total / frames)
    if world()[1] > 1:  # the epoch's mean over every process's frames
        sums = torch.tensor([total, frames], dtype=torch.float64, device=device)
        dist.all_reduce(sums)
        total, frames = float(sums[0]), int(sums[1])
    return total / max(frames, 1), iteration


@torch.no_grad()
def evaluate(
    model: EgoNetModel,
    dataset: FrameDataset,
    *,
    device: torch.device,
    batch_size: int = 4,
    prior: ActionObjectPrior | None = None,
    on_map: Callable[[int, np.ndarray], None] | None = None,
) -> dict[str, float]:
    """Score the model (and optionally the action-object prior) on held-out frames.

    The model sees each frame at the training size; its probabilities are
    resized (bilinear) to the frame's own size and scored there against the
    full-resolution mask, pooled over the frames (``egonet.metrics``).

    Args:
        model: The model (not a DDP wrapper).
        dataset: Held-out frames, not augmented.
        device: Where the model is.
        batch_size: Frames per forward pass.
        prior: The fold's action-object prior, scored on the same frames.
        on_map: Called with ``(item index, float32 (H, W) probabilities at the
            frame's own size)`` for every frame, in order.

    Returns:
        ``loss`` (mean cross-entropy at the training size), ``max_f``, ``ap``,
        and with a prior ``aop_max_f`` and ``aop_ap``; ``{}`` for no frames
        (a fold that holds none out).
    """
    if len(dataset) == 0:
        return {}
    model.eval()
    scores, prior_scores = ScoreAccumulator(), ScoreAccumulator()
    total, frames = 0.0, 0
    for start in range(0, len(dataset), batch_size):
        items = [dataset[i] for i in range(start, min(start + batch_size, len(dataset)))]
        rgb = torch.stack([item["rgb"] for item in items]).to(device)
        dhg = torch.stack([item["dhg"] for item in items]).to(device)
        target = torch.stack([item["mask"] for item in items]).to(device)
        logits = model(rgb, dhg).float()
        total += float(F.cross_entropy(logits, target, reduction="sum")) / target[0].numel()
        frames += len(items)
        probabilities = action_object_probability(logits).cpu().numpy()
        for item, probability in zip(items, probabilities, strict=True):
            mask = dataset.native_mask(item["index"])
            probability = resize_probability(probability, mask.shape)
            scores.add(probability, mask)
            if prior is not None:
                prior_scores.add(prior.predict(np.zeros((*mask.shape, 3), np.uint8)), mask)
            if on_map is not None:
                on_map(item["index"], probability)
    score = scores.score()
    out = {"loss": total / frames, "max_f": score.max_f, "ap": score.ap, "threshold": score.best_threshold}
    if prior is not None:
        aop = prior_scores.score()
        out |= {"aop_max_f": aop.max_f, "aop_ap": aop.ap}
    return out


# --------------------------------------------------------------------------- one fold


@dataclass
class FoldResult:
    """What :func:`fit` leaves: the fold, its checkpoint file and scores.

    Attributes:
        name: The fold (held-out activity, or ``"single"``).
        checkpoint: The checkpoint file (``None`` when nothing was written).
        metrics: Final held-out scores: ``max_f``, ``ap``, ``aop_max_f``,
            ``aop_ap``, ``loss`` (held-out), ``train_loss``, frame counts, ``epochs``.
        history: One dict per epoch: ``epoch``, ``train_loss``, ``lr`` and,
            when evaluated, ``loss``, ``max_f``, ``ap``.
        train_keys: Keys of the training samples.
        test_keys: Keys of the held-out samples.
    """

    name: str
    checkpoint: Path | None
    metrics: dict[str, float]
    history: list[dict[str, float]]
    train_keys: list
    test_keys: list


def fit(
    train_set: FrameDataset,
    test_set: FrameDataset,
    *,
    config: TrainConfig,
    fold: str = "single",
    checkpoint_path: Path | None = None,
    start: Mapping | None = None,
    on_map: Callable[[int, np.ndarray], None] | None = None,
    on_epoch: Callable[[dict], None] | None = None,
    tracker: _Tracker | None = None,
) -> tuple[EgoNetModel, FoldResult]:
    """Train one model on ``train_set`` and score it on ``test_set``.

    Args:
        train_set: Training frames (augmented by the dataset).
        test_set: Held-out frames (not augmented).
        config: The training configuration.
        fold: The fold's name, recorded in the checkpoint.
        checkpoint_path: Where rank 0 writes the checkpoint after every epoch
            (``None``: nowhere).
        start: A loaded checkpoint to continue from (weights, optimiser,
            epoch, RNG); training goes on until ``config.epochs``. An
            interrupted fold continues exactly; a finished one given more
            epochs restarts the poly schedule over the new total (a warm
            restart from the current weights).
        on_map: Receives every held-out probability map of the final
            evaluation, see :func:`evaluate`.
        on_epoch: Receives each epoch's history record once it is complete
            (rank 0): after its evaluation, and for the last epoch after the
            final one, so a live chart never shows a record that changes.
        tracker: Progress bookkeeping shared by the folds of a run.

    Returns:
        The trained model (on its device, eval mode) and the fold's result.

    Raises:
        EgonetError: If ``start`` has already done more epochs than ``config.epochs``.
    """
    device = resolve_device(config.device)
    rank, world_size = setup_distributed(device)
    if learns_classes(config.model):
        # Object-class segmentation (DeepLab-Obj): the classes the fold's *training* frames show, so
        # nothing of the held-out activity (its instances of other classes are background there).
        classes = start["model"]["options"]["classes"] if start is not None else train_set.class_names()
        config = replace(config, model_options={**config.model_options, "classes": list(classes)})
        train_set, test_set = train_set.with_classes(classes), test_set.with_classes(classes)
    model = _initial_model(config, device=device, world_size=world_size, start=start)
    optimizer = torch.optim.SGD(
        model.parameters(), lr=config.learning_rate, momentum=config.momentum, weight_decay=config.weight_decay
    )
    keys = {"train_keys": [s.key for s in _samples(train_set)], "test_keys": [s.key for s in _samples(test_set)]}
    tracker = tracker or _Tracker(steps=0, folds=1, epochs=config.epochs, callback=None)
    run = _FoldRun(config, fold, model, optimizer, device, rank, tracker, checkpoint_path, keys)
    loader = _training_loader(train_set, config, device=device, rank=rank, world_size=world_size)
    lr_at = _poly_schedule(config, iterations=len(loader) * config.epochs)
    if start is not None:
        run.restore(start)
        tracker.skip(run.epoch * len(loader))
    trainer = model if world_size == 1 else DistributedDataParallel(model, device_ids=[device] if device.type == "cuda" else None)
    prior = ActionObjectPrior().fit_masks(train_set.base(i)[2] for i in range(len(train_set)))

    while run.epoch < config.epochs:
        record = run.train_epoch(trainer, loader, lr_at, test_set)
        if run.epoch < config.epochs and on_epoch is not None and rank == 0:
            on_epoch(dict(record))
        _barrier()

    if rank == 0:  # the final scores, and the held-out maps for the caller
        run.finish(train_set, test_set, prior=prior, batch_size=loader.batch_size, on_map=on_map)
        if on_epoch is not None and run.history:
            on_epoch(dict(run.history[-1]))
    _barrier()
    model.eval()
    return model, FoldResult(fold, checkpoint_path if rank == 0 else None, run.metrics, run.history, **keys)


@dataclass
class _FoldRun:
    """A fold under training: what its steps share, and its progress (what its checkpoint records)."""

    config: TrainConfig
    fold: str
    model: EgoNetModel
    optimizer: torch.optim.Optimizer
    device: torch.device
    rank: int
    tracker: _Tracker
    checkpoint_path: Path | None
    keys: dict[str, list]
    epoch: int = 0
    iteration: int = 0
    history: list[dict] = field(default_factory=list)
    metrics: dict = field(default_factory=dict)

    def restore(self, start: Mapping) -> None:
        """Continue a checkpoint: its weights, optimiser, RNG and progress."""
        self.model.load_state_dict(start["state_dict"])
        self.optimizer.load_state_dict(start["optimizer"])
        self.epoch, self.iteration, self.history = int(start["epoch"]), int(start["iteration"]), list(start["history"])
        if self.epoch > self.config.epochs:
            raise EgonetError(
                f"the checkpoint has trained {self.epoch} epochs already: ask for more than {self.epoch}", field="epochs"
            )
        # The torch RNG where the checkpoint left it: the next epoch's loader draws as it would have.
        _set_rng_state(start["rng"])
        self.metrics = dict(start["metrics"])

    def train_epoch(self, trainer: torch.nn.Module, loader: DataLoader, lr_at: Callable[[int], float],
                    test_set: FrameDataset) -> dict:
        """One more epoch: train, score the held-out frames when due (rank 0), save; returns the epoch's record."""
        self.epoch += 1
        # Shuffling and augmentation draw from (seed, epoch): a resumed epoch repeats exactly.
        loader.sampler.set_epoch(self.epoch)
        loader.dataset.set_epoch(self.epoch)
        self.tracker.update(fold=self.fold, epoch=self.epoch, loss=None, phase="train")
        train_loss, self.iteration = train_one_epoch(
            trainer, loader, self.optimizer, device=self.device, lr_at=lr_at, iteration=self.iteration,
            amp=self.config.amp, on_step=lambda loss: self.tracker.update(steps=1, loss=loss),
        )
        record = {"epoch": self.epoch, "train_loss": train_loss, "lr": lr_at(self.iteration - 1)}
        # The last epoch is scored by finish, with the prior and the maps; scoring it here too would be twice.
        every = self.config.eval_every
        if self.epoch < self.config.epochs and every and self.epoch % every == 0 and self.rank == 0:
            self.tracker.update(phase="evaluate")
            record |= evaluate(self.model, test_set, device=self.device, batch_size=loader.batch_size)
        self.history.append(record)
        self.metrics = {"train_loss": train_loss, "epochs": self.epoch}
        self.save(complete=False)
        return record

    def finish(self, train_set: FrameDataset, test_set: FrameDataset, *, prior: ActionObjectPrior, batch_size: int,
               on_map: Callable[[int, np.ndarray], None] | None) -> None:
        """The fold's result from its final evaluation (rank 0); the last epoch's record gets the held-out scores."""
        self.tracker.update(fold=self.fold, epoch=self.epoch, phase="evaluate")
        final = evaluate(self.model, test_set, device=self.device, batch_size=batch_size, prior=prior, on_map=on_map)
        if self.history:
            self.history[-1] |= {k: final[k] for k in ("loss", "max_f", "ap") if k in final}
        train_loss = self.history[-1]["train_loss"] if self.history else None
        self.metrics = {**final, "train_loss": train_loss, "epochs": self.epoch, "train_frames": len(train_set),
                        "test_frames": len(test_set)}
        if "classes" in self.model.config.options:  # an object-class model: how many it learned
            self.metrics["classes"] = len(self.model.config.options["classes"])
        self.save(complete=True)

    def save(self, *, complete: bool) -> None:
        """Rank 0 writes the checkpoint: the format's keys, the optimiser and the RNG state."""
        if self.checkpoint_path is not None and self.rank == 0:
            progress = {"epoch": self.epoch, "iteration": self.iteration, "complete": complete,
                        "metrics": self.metrics, "history": self.history}
            extra = {"optimizer": self.optimizer.state_dict(), "rng": _rng_state()}
            state = checkpoint_state(self.model, self.config, fold=self.fold, **self.keys, **progress, extra=extra)
            save_checkpoint(self.checkpoint_path, state)


def _rng_state() -> dict:
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def _set_rng_state(state: Mapping) -> None:
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def _initial_model(config: TrainConfig, *, device: torch.device, world_size: int, start: Mapping | None) -> EgoNetModel:
    """The fold's model before training: seeded, so every fold and process starts from the same weights.

    A fold that continues a checkpoint is built as that checkpoint's model
    (its options, with the conventions it was trained in), whose weights
    :meth:`_FoldRun.restore` then loads.
    """
    torch.manual_seed(config.seed)
    if start is not None:  # a checkpoint brings its own weights and conventions
        options = saved_options(start["model"]["name"], start["model"]["options"])
    else:
        options = dict(config.model_options) | ({"pretrained": True} if config.pretrained else {})
    model = build_model(config.model, **options)
    if config.init is not None and start is None:
        initialise(model, config.init, sha256=config.init_sha256)
    model = model.to(device)
    if world_size > 1:
        # Gradients of channels-last activations (the lite streams) come in channels-last
        # layout; DDP's buckets copy them fastest when the parameters share it.
        model = model.to(memory_format=torch.channels_last)
    return model


def _training_loader(
    train_set: FrameDataset, config: TrainConfig, *, device: torch.device, rank: int, world_size: int
) -> DataLoader:
    """Shuffled batches of this process's share of the frames (all of them in one process)."""
    sampler = DistributedSampler(train_set, num_replicas=world_size, rank=rank, shuffle=True, seed=config.seed)
    loader = DataLoader(
        train_set, batch_size=max(1, config.batch_size // world_size), sampler=sampler,
        num_workers=config.num_workers, pin_memory=device.type == "cuda", persistent_workers=False,
    )
    return loader


def _poly_schedule(config: TrainConfig, *, iterations: int) -> Callable[[int], float]:
    """DeepLab's "poly" learning rate over a fold's ``iterations``: ``lr * (1 - i / N) ** lr_power``."""

    def lr_at(i: int) -> float:
        # Never quite zero: the last iteration still takes a (small) step.
        return config.learning_rate * (1.0 - min(i, iterations - 1) / iterations) ** config.lr_power

    return lr_at


def _samples(dataset: FrameDataset) -> Iterator[Sample]:
    return (dataset.sample(i) for i in range(len(dataset)))


# --------------------------------------------------------------------------- the run


def fold_slug(name: str) -> str:
    """A file-name-safe form of a fold name ("desk work" -> "desk-work")."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", name).strip("-") or "fold"


def cross_validate(
    samples: Sequence[Sample],
    config: TrainConfig,
    *,
    out_dir: str | Path,
    folds: Sequence[Fold] | None = None,
    start: Mapping | None = None,
    on_progress: Callable[[Progress], None] | None = None,
    on_fold_end: Callable[[FoldResult], None] | None = None,
    on_map: Callable[[str, Sample, np.ndarray], None] | None = None,
    on_epoch: Callable[[str, dict], None] | None = None,
) -> list[FoldResult]:
    """Train and score every fold: the outer loop.

    Writes ``out_dir/config.json`` (the resolved configuration) and one
    checkpoint per fold, ``out_dir/<fold>.pt``, after every epoch. A fold
    whose checkpoint exists continues from it; a complete one is only
    evaluated again (so its held-out maps reach ``on_map`` once more).

    Args:
        samples: The labelled frames (``Sample.group`` is the activity).
        config: The training configuration.
        out_dir: Folder for the checkpoints and ``config.json``.
        folds: Explicit folds (positions in ``samples``); by default
            :func:`make_folds` with ``config.folds``.
        start: A loaded checkpoint to continue; needs exactly one fold.
        on_progress: Progress reports (rank 0); may raise :class:`egonet.errors.Cancelled`.
        on_fold_end: Called with each fold's result (rank 0).
        on_map: Called with ``(fold, sample, float32 (H, W) probabilities at
            the frame's own size)`` for every held-out frame (rank 0).
        on_epoch: Called with ``(fold, history record)`` as each epoch's
            record is complete (rank 0), see :func:`fit`.

    Returns:
        The folds' results, in order (rank 0; other ranks get empty metrics).

    Raises:
        ValueError: Bad configuration, too few frames or activities, or a
            frame that cannot be read (the message names it).
    """
    out_dir = Path(out_dir)
    device = resolve_device(config.device)
    rank, world_size = setup_distributed(device)
    dataset = FrameDataset(samples, size=config.size, seed=config.seed)
    folds = list(folds) if folds is not None else make_folds(dataset.groups, mode=config.folds, test_fraction=config.test_fraction)
    if start is not None and len(folds) != 1:
        raise EgonetError("continuing a checkpoint trains exactly one fold", field="start")
    steps = _planned_steps(folds, config, world_size=world_size)
    tracker = _Tracker(steps=steps, folds=len(folds), epochs=config.epochs, callback=on_progress)
    if rank == 0:
        _write_config(out_dir, config, folds, device=device, world_size=world_size)

    results = []
    for index, fold in enumerate(folds):
        path = out_dir / f"{fold_slug(fold.name)}.pt"
        state = start
        if state is None and path.exists():
            state = load_checkpoint(path)  # resume this fold where it stopped
        train_set = dataset.subset(fold.train, augment=config.augment)
        test_set = dataset.subset(fold.test, augment=None)
        tracker.update(fold=fold.name, fold_index=index, epoch=0, loss=None, phase="train")

        def fold_map(i: int, probability: np.ndarray, name: str = fold.name, held_out: FrameDataset = test_set) -> None:
            on_map(name, held_out.sample(i), probability)

        def fold_epoch(record: dict, name: str = fold.name) -> None:
            on_epoch(name, record)

        _, result = fit(
            train_set, test_set, config=config, fold=fold.name, checkpoint_path=path, start=state,
            on_map=fold_map if on_map is not None else None,
            on_epoch=fold_epoch if on_epoch is not None else None, tracker=tracker,
        )
        if rank == 0 and on_fold_end is not None:
            on_fold_end(result)
        results.append(result)
    tracker.update(phase="done")
    return results


def _planned_steps(folds: Sequence[Fold], config: TrainConfig, *, world_size: int) -> int:
    """Optimiser steps of the whole run: each process takes its share of a fold's frames per epoch."""
    per_process = max(1, config.batch_size // world_size)
    return sum(config.epochs * math.ceil(math.ceil(len(f.train) / world_size) / per_process) for f in folds)


def _write_config(out_dir: Path, config: TrainConfig, folds: Sequence[Fold], *, device: torch.device, world_size: int) -> None:
    """``out_dir/config.json``: the resolved configuration, where it ran and the folds, beside the checkpoints."""
    out_dir.mkdir(parents=True, exist_ok=True)
    resolved = config.to_dict() | {"lr": config.learning_rate}
    environment = {"device": str(device), "world_size": world_size, "torch": torch.__version__}
    plan = [{"fold": f.name, "train_frames": len(f.train), "test_frames": len(f.test)} for f in folds]
    (out_dir / "config.json").write_text(json.dumps({"config": resolved, "environment": environment, "folds": plan}, indent=2))
