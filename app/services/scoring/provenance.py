"""How a score report was made: the facts every format carries, the methods paragraph, the citation.

A :class:`Provenance` holds the settings behind a report's numbers (the
convention, the threshold grid, the frames, the policy for frames without
action-object pixels and how many there were, the bootstrap, whether the
test is paired, how people's clicks became maps, the code version). Every
renderer writes it: text and LaTeX as ``Label: sentence`` lines
(:meth:`Provenance.facts`), the CSV as columns repeated on every line
(:meth:`Provenance.columns`), JSON at the top (:meth:`Provenance.as_dict`)
and the page above the tables; ``methods`` writes the same facts, with the
table's frames, as a methods paragraph; :data:`BIBTEX` cites the seed paper
(the facts are those of ``shared/seed/`` and ``shared/docs/egonet-reference.md``).

:func:`p_text` is the one way a p-value is written: with B resamples none is
below ``1 / (B + 1)``, and one at that floor is written ``< 0.001`` (the
floor rounded up to one significant figure), never as a number.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from app.services.scoring.cells import COLUMNS, FRAMES, METRIC_TITLES
from egonet.metrics import DEFAULT_EMPTY, DEFAULT_RESAMPLES, DEFAULT_THRESHOLDS, MIN_FRAMES, PER_FRAME_MEANS, p_floor, threshold_values

CI_METHOD = "BCa (bias-corrected and accelerated) bootstrap over frames, resampled within each activity"
CI_METHOD_SEQUENCES = "BCa (bias-corrected and accelerated) bootstrap over frames, resampled within each column (recording)"
CI_LEVEL = 0.95

EMPTY_TITLES = {
    "leave-out": "left out of the per-frame means (our choice: the paper does not say)",
    "zero": "each scores 0 whatever the map",
    "one-if-empty": "each scores 1 at the thresholds where the map predicts nothing, else 0",
}
"""What each policy for frames without action-object pixels does (``egonet.metrics.EMPTY_POLICIES``)."""

BIBTEX = """@inproceedings{bertasius2017egonet,
  author    = {Gedas Bertasius and Hyun Soo Park and Stella X. Yu and Jianbo Shi},
  title     = {First-Person Action-Object Detection with {EgoNet}},
  booktitle = {Robotics: Science and Systems (RSS)},
  year      = {2017}
}
"""
"""The seed paper: title and authors from its source in ``shared/seed/``, venue and year from the reference doc."""


def p_text(p: float | None, resamples: int) -> str:
    """A p-value as every format writes it: ``"0.012"``, ``"< 0.001"`` at the floor ``1 / (B + 1)``, ``"-"`` without one.

    Example:
        >>> p_text(1 / 1001, 1000), p_text(0.0123, 1000), p_text(0.5, 100)
        ('< 0.001', '0.012', '0.500')
    """
    if p is None:
        return "-"
    floor = p_floor(resamples)
    if p <= floor * (1 + 1e-9):
        exponent = math.floor(math.log10(floor))
        digit = math.ceil(round(floor / 10**exponent, 9))  # one significant figure, rounded up: 1/1001 -> 0.001
        if digit == 10:
            digit, exponent = 1, exponent + 1
        return f"< {digit * 10**exponent:.{max(0, -exponent)}f}"
    return f"{p:.3f}" if p >= 0.001 else f"{p:.2g}"


@dataclass(frozen=True)
class HumanMaps:
    """How one study ran and how its clicks became soft maps (the facts its rows were made from).

    Attributes:
        study: ``study 3 "name"``.
        regions: The superpixel regions, in words.
        sigma: The click Gaussian's width, in words.
        rows: The keys of its rows in the table.
        frames: Timed (scored) frames each participant was shown, and
            ``per_activity`` of them from each of ``activities`` activities.
        seed: The seed of the frames' random draw.
        order: ``shuffled`` or ``counterbalanced``.
        practice: Practice trials before the timed part (never scored).
        catch: Attention-check (catch) trials among them (never scored).
        pilots: Pilot participants, left out of the scores.
        failed_checks: Participants who failed a comprehension or attention check.
        excluded: Whether those were left out of the scores.
    """

    study: str
    regions: str
    sigma: str
    rows: tuple[str, ...] = ()
    frames: int = 0
    per_activity: int = 0
    activities: int = 0
    seed: int | None = None
    order: str = "shuffled"
    practice: int = 0
    catch: int = 0
    pilots: int = 0
    failed_checks: int = 0
    excluded: bool = False


@dataclass(frozen=True)
class Provenance:
    """The settings behind a report's numbers (see the module).

    Attributes:
        metric: The convention (``egonet.metrics.METRICS``).
        thresholds: The number T of thresholds ``k / (T + 1)``.
        frames: ``shared`` or ``each``.
        empty: The policy for frames without action-object pixels.
        empty_frames: Per activity, the frames without action-object pixels
            among the rows' frames.
        answered_only: Whether people's unanswered trials were left out.
        resamples: Bootstrap resamples B (0: no intervals).
        seed: The bootstrap's seed.
        paired: Whether the numbers are paired differences (a comparison).
        human_maps: For each study with rows, how it ran and how its clicks became maps.
        model_splits: For each model row (a run, and a group's runs), how
            it was split: ``loao``, ``single``, ``released`` or ``all``.
        trained_on: The table's training set: the activities every learned
            row was trained on, none of them scored (the paper's Tables 3
            and 4); () for leave-one-activity-out (Table 2).
        training_frames: The labelled frames of each of those activities.
        column_kind: What the columns are: ``activities`` or ``sequences`` (each activity's recordings).
        code_version: ``app.version.code_version()`` when the report was made.
        ground_truth: For each activity whose ground truth was made from
            attention points (``app.services.attention_points``), how, in words;
            the others' is masks drawn (or imported) by people.
        predicted_depth: Per activity, the scored frames whose depth and DHG
            a network predicted from the RGB (``flask egonet predict-depth``).
    """

    metric: str = "pooled"
    thresholds: int = DEFAULT_THRESHOLDS
    frames: str = "shared"
    empty: str = DEFAULT_EMPTY
    empty_frames: Mapping[str, int] = field(default_factory=dict)
    answered_only: bool = False
    resamples: int = DEFAULT_RESAMPLES
    seed: int = 0
    paired: bool = False
    human_maps: Sequence[HumanMaps] = ()
    model_splits: Mapping[str, str] = field(default_factory=dict)
    trained_on: Sequence[str] = ()
    training_frames: Mapping[str, int] = field(default_factory=dict)
    column_kind: str = "activities"
    code_version: str = ""
    ground_truth: Mapping[str, str] = field(default_factory=dict)

    def ground_truth_text(self) -> str:
        """Where the ground truth came from: ``kids: attention points, sigma 15 px, ...; other activities: drawn masks``."""
        return "; ".join([*(f"{a}: {t}" for a, t in self.ground_truth.items()), "other activities: drawn masks"])
    predicted_depth: Mapping[str, int] = field(default_factory=dict)

    def p_text(self, p: float | None) -> str:
        return p_text(p, self.resamples)

    def floor_text(self) -> str:
        """How a p-value at the floor ``1 / (B + 1)`` is written (``"< 0.001"``)."""
        return p_text(p_floor(self.resamples), self.resamples)

    def grid(self) -> str:
        return f"{self.thresholds} thresholds t_k = k/{self.thresholds + 1}, k = 1..{self.thresholds}, positive where p >= t_k"

    def empty_text(self) -> str:
        """How many frames had no action-object pixels, and what the convention did with them."""
        total = sum(self.empty_frames.values())
        where = ", ".join(f"{a} {n}" for a, n in self.empty_frames.items() if n)
        count = f"{total} ({where})" if total else "none"
        if self.metric in PER_FRAME_MEANS:
            return f"{count}; policy {self.empty}: {EMPTY_TITLES[self.empty]}"
        return f"{count}; {self.metric} counts their false positives (policy {self.empty} applies to the per-frame means only)"

    def ci_method(self) -> str:
        return CI_METHOD_SEQUENCES if self.column_kind == "sequences" else CI_METHOD

    def ci_text(self) -> str:
        if not self.resamples:
            return "none (0 resamples)"
        text = (f"{self.ci_method()}, {self.resamples} resamples, seed {self.seed}; none (n too small) where an activity "
                f"has fewer than {MIN_FRAMES} frames")  # fmt: skip
        if self.paired:
            return (f"{text}; paired: both rows on the same resamples of the frames they share; p two-sided, "
                    f"written {self.floor_text()} at its floor 1/(B+1)")  # fmt: skip
        return f"{text}; not paired: each cell's interval on its own frames"

    def training_text(self) -> str:
        """What the learned rows were trained on."""
        if not self.trained_on:
            return ("per row: each model on its own held-out frames, the learned baselines fitted per "
                    "leave-one-activity-out fold")  # fmt: skip
        frames = ", ".join(f"{a} {self.training_frames.get(a, 0)}" for a in self.trained_on)
        return (f"trained on: {', '.join(self.trained_on)} ({sum(self.training_frames.values())} labelled frames: {frames}); "
                "every model and learned baseline trained on those frames only, scored on the other activities")  # fmt: skip

    def facts(self) -> list[tuple[str, str]]:
        """``(label, sentence)`` pairs, in the order every format writes them."""
        people = "answered trials only" if self.answered_only else "a trial without an answer counts as an empty map"
        out = [
            ("Metric", f"{self.metric} - {METRIC_TITLES[self.metric]}; {self.grid()}"),
            ("Frames", f"{self.frames} - {FRAMES[self.frames]}; people: {people}"),
            ("95% CI", self.ci_text()),
            ("Frames without action-object pixels", self.empty_text()),
            ("Training set", self.training_text()),
            ("Columns", f"{self.column_kind} - {COLUMNS[self.column_kind]}"),
        ]
        if self.ground_truth:
            out.append(("Ground truth", self.ground_truth_text()))
        out += [("People's maps", f"{m.study}: {m.regions}; click Gaussians of {m.sigma}") for m in self.human_maps]
        if depth := self.predicted_depth_text():
            out.append(("Depth", depth))
        return [*out, ("Code", self.code_version or "unknown")]

    def predicted_depth_text(self) -> str:
        """``"DHG from predicted depth: 12 frames (gaze 12)"``, or ``""`` when every scored frame's depth was measured."""
        total = sum(self.predicted_depth.values())
        if not total:
            return ""
        where = ", ".join(f"{a} {n}" for a, n in self.predicted_depth.items() if n)
        return f"DHG from predicted depth: {total} frame{'' if total == 1 else 's'} ({where}), depth predicted from RGB by a network"

    def columns(self) -> dict[str, Any]:
        """The facts as flat CSV columns (the same values on every line)."""
        return {
            "thresholds": self.thresholds,
            "empty frames policy": self.empty,
            "empty frames": sum(self.empty_frames.values()),
            "answered only": int(self.answered_only),
            "resamples": self.resamples,
            "bootstrap seed": self.seed,
            "ci": f"BCa {CI_LEVEL:.0%}" if self.resamples else "",
            "min frames": MIN_FRAMES,
            "paired": int(self.paired),
            "trained on": ", ".join(self.trained_on) or "leave-one-activity-out",
            "columns": self.column_kind,
            "people's maps": " | ".join(f"{m.study}: {m.regions}; click Gaussians of {m.sigma}" for m in self.human_maps),
            "ground truth": self.ground_truth_text() if self.ground_truth else "drawn masks",
            "code version": self.code_version,
        }

    def as_dict(self) -> dict[str, Any]:
        """The facts for JSON; ``frames`` and ``metric`` first."""
        return {
            "frames": self.frames,
            "metric": self.metric,
            "answered_only": self.answered_only,
            "thresholds": self.thresholds,
            "threshold_values": threshold_values(self.thresholds).tolist(),
            "empty_frames": {"policy": self.empty, "count": sum(self.empty_frames.values()), "by_activity": dict(self.empty_frames),
                             "applies": self.metric in PER_FRAME_MEANS, "means": EMPTY_TITLES[self.empty]},  # fmt: skip
            "ci": {"level": CI_LEVEL, "method": self.ci_method(), "resamples": self.resamples, "seed": self.seed, "paired": self.paired,
                   "p_floor": p_floor(self.resamples) if self.resamples else None, "min_frames": MIN_FRAMES},  # fmt: skip
            "human_maps": [asdict(m) | {"rows": list(m.rows)} for m in self.human_maps],
            "model_splits": dict(self.model_splits),
            "columns": self.column_kind,
            "trained_on": {"activities": list(self.trained_on), "frames": dict(self.training_frames)} if self.trained_on else None,
            "ground_truth": dict(self.ground_truth),
            "predicted_depth_frames": dict(self.predicted_depth),
            "code_version": self.code_version,
        }
