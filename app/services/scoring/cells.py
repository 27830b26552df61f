"""The score table's parts: its labels and definitions, cells, curves, rows and paired differences.

``table`` builds the :class:`~app.services.scoring.table.Report` and the
:class:`~app.services.scoring.table.Comparison` from them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from egonet.metrics import MIN_FRAMES

ALL = "all"
"""The key of a row's result pooled over all its frames."""
MEAN = "mean"
"""The column of the unweighted mean over activities."""

MODEL, BASELINE, HUMAN = "model", "baseline", "human"
KIND_TITLES = {MODEL: "Models", BASELINE: "Baselines", HUMAN: "People (MF only)"}

COLUMNS = {
    "activities": "one column per activity",
    "sequences": "one column per recording (sequence) of each activity, named activity / sequence",
}
"""What a table's columns can be (``build_report(columns=...)``); each column is resampled on its own."""

FRAMES = {
    "shared": "each activity's frames that every row scored there has (their intersection)",
    "each": "all the frames each row has; best marked only among rows scored on the same frames",
}
"""The frame choices and what they mean."""

STATISTIC_LABELS = {
    "pooled": {"max_f": "MF", "ap": "AP"},
    "ois-mean": {"max_f": "mean F", "ap": "mean AP"},
    "mean-curve": {"max_f": "mean-curve MF", "ap": "mean-curve AP"},
    "ods-ois": {"max_f": "ODS", "ois": "OIS", "ap": "AP"},
}
"""Column labels of each convention's statistics, in the order they are shown."""

METRIC_TITLES = {
    "pooled": "Pooled: max F and AP of the pixel counts summed over all frames of an activity",
    "ois-mean": "OIS-mean: the mean over frames of each frame's best F (at its own threshold), and of each frame's AP",
    "mean-curve": "Mean curve: max F and AP of the precision-recall curve averaged over frames",
    "ods-ois": "BSDS ODS / OIS: best F at one threshold for the activity (ODS), at each frame's own (OIS), and AP",
}

METRIC_SHORT = {
    "pooled": "pixels pooled per activity (default)", "ois-mean": "mean of each frame's best F",
    "mean-curve": "best F of the mean curve", "ods-ois": "BSDS ODS / OIS",
}  # fmt: skip
"""What the metric selector says beside each convention's name."""

METRIC_DEFINITIONS = {
    "pooled": (
        "MF is the maximum over thresholds of F = 2PR / (P + R) and AP the average precision, sum over k of "
        "(R_k - R_{k+1}) P_k, with P = TP / (TP + FP) (1 when nothing is predicted) and R = TP / (TP + FN) "
        "computed from the pixel counts summed over all the frames of the activity."
    ),
    "ois-mean": (
        "Each frame gets its own precision-recall curve; mean F is the mean over frames of each frame's best F "
        "(at its own best threshold) and mean AP the mean of the frames' APs."
    ),
    "mean-curve": (
        "Each frame gets its own precision P_k and recall R_k at each threshold; these are averaged over the frames, "
        "and mean-curve MF is the maximum over thresholds of F of the averaged curve, mean-curve AP its average precision."
    ),
    "ods-ois": (
        "ODS (optimal dataset scale) is the best F at one threshold for all frames of the activity, from pooled "
        "counts (the pooled MF); OIS (optimal image scale) is F of the counts summed over frames each taken at "
        "its own best threshold (the highest on ties); AP is the pooled average precision."
    ),
}

COMMON_DEFINITION = (
    "Thresholds t_k = k / (T + 1), k = 1..T (T = 99: 0.01 .. 0.99), a pixel being positive when its probability "
    "is >= t_k (maps are never normalised). Models are scored on held-out frames only; the learned "
    "baselines (AOP, Judd, FP-MCG, salObj+depth) are fitted on the other activities' labelled frames "
    "(leave-one-activity-out); people on the frames "
    "of their trials, MF only. The mean column is the unweighted mean of the per-activity values. 95% intervals: "
    f"BCa bootstrap over frames, resampled within each activity; none where an activity has fewer than {MIN_FRAMES} "
    "frames (n too small)."
)

# Line colours of the precision-recall plots, one per row in table order.
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")


_WORDS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine")


def count(n: int, one: str, many: str | None = None) -> str:
    """``"one participant"``, ``"12 participants"``: a count of things in words below ten, with its noun's number."""
    return f"{_WORDS[n] if 0 <= n < len(_WORDS) else n} {one if n == 1 else many or one + 's'}"


def frames_text(n: int) -> str:
    """``"1 frame"``, ``"13 frames"``: frame counts stay numerals (they are the table's n)."""
    return f"{n} frame{'' if n == 1 else 's'}"


def too_few(*frames: int) -> bool:
    """Whether a statistic resampled over activities with these numbers of frames is "n too small" (no interval, no p-value)."""
    return min(frames) < MIN_FRAMES


def definition(metric: str) -> str:
    """The full definition of a convention's numbers (for the page, the downloads and the JSON)."""
    return f"{METRIC_DEFINITIONS[metric]} {COMMON_DEFINITION}"


@dataclass(frozen=True)
class Cell:
    """One (row, column) result.

    Attributes:
        n_frames: Frames scored (0: the row has frames there, none shared).
        values: The convention's statistics (``max_f``, ``ap``, ``ois``);
            None for people's AP and where no frame was scored.
        ci: The 95 % interval of each statistic, None where the value is.
        sd: For a group of seeds, the standard deviation of each statistic
            across the seeds; None otherwise.
        frames_available: Frames the row has there (before the shared cut).
        frames_key: A fingerprint of the frames scored; cells with the same
            key were scored on the same frames.
        activities: For the mean, how many activities it averages.
        too_few: "n too small": an activity it resamples has fewer than
            ``egonet.metrics.MIN_FRAMES`` frames, so it has no interval.
    """

    n_frames: int
    values: Mapping[str, float | None] = field(default_factory=dict)
    ci: Mapping[str, tuple[float, float] | None] = field(default_factory=dict)
    sd: Mapping[str, float | None] | None = None
    frames_available: int = 0
    frames_key: str = ""
    activities: int = 1
    too_few: bool = False

    @property
    def max_f(self) -> float | None:
        return self.values.get("max_f")

    @property
    def ap(self) -> float | None:
        return self.values.get("ap")

    @property
    def no_shared_frames(self) -> bool:
        return self.n_frames == 0


@dataclass(frozen=True)
class Curve:
    """A pooled precision-recall curve over increasing thresholds, and where F is largest."""

    precision: tuple[float, ...]
    recall: tuple[float, ...]
    best: int


@dataclass
class Row:
    """One line of the table: a run, a group of runs that differ only in their seed, a baseline or a participant.

    Attributes:
        key: Stable identifier (``run:3``, ``seeds:3,5,7``, ``baseline:aop``, ``participant:12``).
        name: Shown in the table (``egonet-lite (run 3)``, ``AOP``, ``P01``).
        kind: ``model``, ``baseline`` or ``human``.
        detail: A longer description (run name and folds, study name).
        cells: Results by activity name.
        mean: The unweighted mean over the activities with a value (None without any).
        overall: The result on all the row's frames together (None without any).
        curves: Pooled curves by activity and :data:`ALL` (a group has none: its seeds do).
        unanswered: For a participant, trials without an answer (scored as
            empty maps unless the report keeps answered trials only).
        members: For a group of seeds, its runs' rows (on the group's frames).
        group: For a run of a group, the group's key.
        seed: For a run, its seed.
    """

    key: str
    name: str
    kind: str
    detail: str
    cells: dict[str, Cell]
    mean: Cell | None
    overall: Cell | None
    curves: dict[str, Curve]
    unanswered: int | None = None
    members: list[Row] = field(default_factory=list)
    group: str | None = None
    seed: int | None = None


@dataclass(frozen=True)
class Difference:
    """A paired difference (row A minus row B) of one statistic on the frames both rows have.

    ``too_few``: "n too small", as a :class:`Cell`'s: no interval and no p-value.
    """

    value: float
    ci: tuple[float, float] | None
    p_value: float | None
    n_frames: int
    too_few: bool = False
