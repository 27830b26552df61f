"""The paper's Figure 3 for any checkpoint and frame: each pathway's mean fc7 over the frame, with a colour bar.

``egonet`` computes the maps (``NetworkPredictor.activations``: each
stream's fc7 after its ReLU, averaged over channels, upsampled to the
frame); this module picks the frame's inputs, says why a pathway is absent
(the model has no such stream, or the frame has no DHG image), and draws
the figure with matplotlib: the RGB and DHG inputs on top, each pathway's
map over its input below, each with its own colour bar.

A figure is cached under ``CACHE_ROOT/activations/`` by checkpoint and
frame media (safe to delete). A page request computes one only for models
of at most ``ACTIVATIONS_INLINE_MAX_PARAMS`` parameters (default 5 M:
egonet-lite's 1.6 M take about 20 ms of CPU a pass at a small run's size, the
figure about 0.4 s; the VGG variants' 65-139 M take seconds and gigabytes);
larger ones are drawn by
``flask egonet activations``, which fills the same cache, so the page shows
them afterwards.
"""

from __future__ import annotations

import functools
import io as bytes_io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from flask import current_app

from app.errors import Problem
from app.models import Frame
from app.models.training import Checkpoint
from app.services import media
from app.services.training import files as checkpoint_files
from egonet import io
from egonet.network.activations import LAYERS, pathways
from egonet.network.builders import build_model

TITLES = {"rgb": "RGB pathway", "dhg": "DHG pathway", "joint": "single stream (RGB + DHG + XY)"}


class TooLargeForRequest(Problem):
    """A model too large to run inside a page request; the command line draws it."""


@dataclass
class Activations:
    """The maps of one checkpoint on one frame, and why a pathway has none."""

    maps: dict[str, np.ndarray] = field(default_factory=dict)  # pathway -> (H, W) float32
    channels: dict[str, int] = field(default_factory=dict)
    absent: dict[str, str] = field(default_factory=dict)  # pathway -> why
    model: str = ""


def parameter_count(checkpoint: Checkpoint) -> int:
    """The checkpoint's model size, from its run's name and options (no memory, no file)."""
    return _parameter_count(checkpoint.run.model_name, json.dumps(checkpoint.run.model_options or {}, sort_keys=True))


@functools.lru_cache(maxsize=64)
def _parameter_count(model_name: str, options: str) -> int:
    """Built on the meta device once per model and options (a frame page asks on every view)."""
    with torch.device("meta"):
        model = build_model(model_name, **json.loads(options))
    return sum(p.numel() for p in model.parameters())


def _figure_name(checkpoint: Checkpoint, frame: Frame) -> str:
    dhg = Path(frame.dhg_path).stem if frame.dhg_path else "none"
    return f"activations/ckpt{checkpoint.id}-{frame.content_hash}-{dhg}.png"


def cache_path(checkpoint: Checkpoint, frame: Frame) -> Path:
    return media.derived_path(_figure_name(checkpoint, frame))


def inline_limit() -> int:
    return int(current_app.config["ACTIVATIONS_INLINE_MAX_PARAMS"])


def figure_path(checkpoint: Checkpoint, frame: Frame, *, in_request: bool) -> Path:
    """The figure's PNG, drawn and cached on first use.

    Raises:
        TooLargeForRequest: ``in_request`` and the model is larger than ``ACTIVATIONS_INLINE_MAX_PARAMS``
            (and no figure is cached yet).
        Problem: an unreadable checkpoint, or a frame the model cannot read at all.
    """

    def make() -> bytes:
        if in_request and (message := page_message(checkpoint, frame)) is not None:
            raise TooLargeForRequest(message, field="checkpoint", status=409)
        return figure_png(compute(checkpoint, frame), frame, checkpoint)

    return media.derived(_figure_name(checkpoint, frame), make)


def compute(checkpoint: Checkpoint, frame: Frame) -> Activations:
    """Each pathway's map for the frame (see ``NetworkPredictor.activations``), and why the others are absent."""
    from egonet.predictor import NetworkPredictor

    try:
        predictor = NetworkPredictor.from_checkpoint(checkpoint_files.load(checkpoint.path))
    except (ValueError, OSError) as exc:
        raise Problem(f"checkpoint {checkpoint.id} cannot be read: {exc}", field="checkpoint") from None
    streams = pathways(predictor.model)
    name = checkpoint.run.model_name
    out = Activations(model=name, channels={p: int(s.out_channels) for p, s in streams.items()})
    for pathway in ("rgb", "dhg"):
        if "joint" not in streams and pathway not in streams:
            out.absent[pathway] = f"{name} has no {pathway.upper()} pathway"
    if frame.dhg_path is None and predictor.model.uses_dhg:
        for pathway in ("dhg", "joint"):
            if pathway in streams:
                out.absent[pathway] = "this frame has no DHG image: the DHG pathway cannot run"
        if "rgb" not in streams:
            raise Problem(f"frame {frame.id} has no DHG image and {name} reads only DHG: nothing to show", field="frame")
    rgb = io.read_image(media.local_path(frame.rgb_path))
    dhg = io.read_dhg(media.local_path(frame.dhg_path)) if frame.dhg_path and predictor.model.uses_dhg else None
    out.maps = predictor.activations(rgb, dhg)
    return out


def figure_png(found: Activations, frame: Frame, checkpoint: Checkpoint) -> bytes:
    """Figure 3's layout: the inputs on top, each pathway's mean fc7 over its input below, with colour bars."""
    import matplotlib  # imported here: it reads its font cache when loaded

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    rgb = io.read_image(media.local_path(frame.rgb_path))
    dhg = io.read_dhg(media.local_path(frame.dhg_path)) if frame.dhg_path else None
    columns = ["joint"] if "joint" in found.channels else ["rgb", "dhg"]
    aspect = frame.height / frame.width
    figure = Figure(figsize=(4.6 * len(columns) + 0.6, 2 * 4.0 * aspect + 1.6), dpi=110)
    axes = figure.subplots(2, len(columns), squeeze=False)
    inputs = {"rgb": rgb, "dhg": dhg, "joint": rgb}
    for col, pathway in enumerate(columns):
        top, bottom = axes[0][col], axes[1][col]
        shown = inputs[pathway]
        for ax in (top, bottom):
            ax.set_xticks([])
            ax.set_yticks([])
        if shown is not None:
            top.imshow(shown)
        else:
            top.text(0.5, 0.5, "no DHG image", ha="center", va="center", transform=top.transAxes)
        top.set_title({"rgb": "RGB input", "dhg": "DHG input (gray, height, depth)", "joint": "RGB input"}[pathway], fontsize=9)
        values = found.maps.get(pathway)
        if values is None:
            bottom.text(0.5, 0.5, "absent:\n" + found.absent.get(pathway, "not computed"), ha="center", va="center",
                        wrap=True, fontsize=9, transform=bottom.transAxes)
            bottom.set_title(TITLES[pathway], fontsize=9)
            continue
        base = shown if shown is not None else rgb
        bottom.imshow(np.dot(base[..., :3].astype(np.float32), [0.299, 0.587, 0.114]), cmap="gray", vmin=0, vmax=255)
        image = bottom.imshow(values, cmap="turbo", alpha=0.6, vmin=0.0, vmax=max(float(values.max()), 1e-6))
        bar = figure.colorbar(image, ax=bottom, fraction=0.046, pad=0.02)
        bar.set_label("mean activation", fontsize=8)
        bar.ax.tick_params(labelsize=7)
        bottom.set_title(f"{TITLES[pathway]}: {LAYERS[pathway]}, mean of {found.channels[pathway]} channels", fontsize=9)
    figure.suptitle(f"Frame {frame.id} · checkpoint {checkpoint.id} (run {checkpoint.run_id}, {found.model}, "
                    f"fold {checkpoint.fold})", fontsize=10)
    out = bytes_io.BytesIO()
    figure.savefig(out, format="png", bbox_inches="tight", metadata={"Software": None})
    return out.getvalue()


def checkpoint_choices(limit: int = 200) -> list[tuple[int, str]]:
    """The checkpoints of finished runs, newest first, as (id, label) for the frame page's chooser."""
    from app.extensions import db
    from app.models.training import RunStatus, TrainingRun

    rows = db.session.execute(
        db.select(Checkpoint).join(TrainingRun).where(TrainingRun.status == RunStatus.DONE)
        .order_by(Checkpoint.id.desc()).limit(limit)
    ).scalars()
    def model(run: TrainingRun) -> str:
        return "" if run.model_name in run.name else f" ({run.model_name})"

    return [(c.id, f"checkpoint {c.id}: run #{c.run_id} {c.run.name}{model(c.run)}, fold {c.fold}") for c in rows]


def page_message(checkpoint: Checkpoint, frame: Frame) -> str | None:
    """Why the frame page cannot draw this figure in a request (None: it can, or it is cached)."""
    if cache_path(checkpoint, frame).exists() or (n := parameter_count(checkpoint)) <= inline_limit():
        return None
    return (f"{checkpoint.run.model_name} ({n / 1e6:.1f} M parameters) is too large to run in a page request: "
            f"draw it with `flask egonet activations {checkpoint.id} {frame.id} --out FILE.png`, then reload")
