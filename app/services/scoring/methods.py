"""The methods paragraph: what a score table did, in plain English, from the facts it was made from.

Every number comes from the report itself: the frames of each kind of row
from its cells (the n the table prints), the settings from its
:class:`~app.services.scoring.provenance.Provenance` (convention,
thresholds, frame mode, bootstrap, how each study ran and made its maps,
how each model was split). A sentence per kind of row says what that kind
was scored on, so the paragraph cannot claim "every labelled frame" for
rows that were cut to the shared frames, nor one frame count for rows that
stood on different frames.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from app.services.scoring.cells import BASELINE, HUMAN, METRIC_TITLES, MODEL, Row, count, frames_text
from app.services.scoring.provenance import EMPTY_TITLES, HumanMaps, Provenance
from egonet.baselines import is_trained
from egonet.metrics import MIN_FRAMES, PER_FRAME_MEANS

SPLITS = {
    "loao": "trained with leave-one-activity-out cross-validation (each activity's frames predicted by the model trained on the other activities)",
    "single": "trained on a single split, its held-out frames the last part of every activity",
    "released": "imported from the authors' release, never trained on these frames",
    "all": "trained on every labelled frame of the training activities, none held out",
}
"""What each way of splitting a model's frames means (``TrainingRun.folds``)."""


def _listed(items: Sequence[str]) -> str:
    """``"a"``, ``"a and b"``, ``"a, b and c"``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _per_activity(row: Row) -> dict[str, int]:
    return {a: c.n_frames for a, c in row.cells.items() if c.n_frames}


def _breakdown(per_activity: Mapping[str, int]) -> str:
    return ", ".join(f"{a} {n}" for a, n in per_activity.items())


def rows_frames(rows: Sequence[Row]) -> str:
    """The frames some rows were scored on: ``"42 frames (cooking 6, ...)"``, ``"56 frames each"``, ``"50 to 56 frames each"``."""
    scored = [_per_activity(r) for r in rows]
    totals = [sum(f.values()) for f in scored]
    if all(f == scored[0] for f in scored):
        return f"{frames_text(totals[0])}{' each' if len(rows) > 1 else ''} ({_breakdown(scored[0])})"
    if len(set(totals)) == 1:
        return f"{frames_text(totals[0])} each"
    return f"{min(totals)} to {frames_text(max(totals))} each"


def _available(rows: Sequence[Row]) -> str:
    """What some rows had before the shared cut: ``"42 frames"`` or ``"50 to 56 frames each"``."""
    totals = sorted({sum(c.frames_available for c in r.cells.values()) for r in rows})
    if len(totals) == 1:
        return frames_text(totals[0]) + (" each" if len(rows) > 1 else "")
    return f"{totals[0]} to {frames_text(totals[-1])} each"


def paragraph(rows: Sequence[Row], provenance: Provenance, *, activities: Sequence[str], frames_per_activity: Mapping[str, int]) -> str:
    """A report's methods paragraph (one line of plain text).

    Args:
        rows: The report's top-level rows, in table order.
        provenance: How the report was made.
        activities: Its columns.
        frames_per_activity: Frames scored in each activity (the most any row has there).
    """
    p = provenance
    by_kind = {kind: [r for r in rows if r.kind == kind] for kind in (MODEL, BASELINE, HUMAN)}
    parts = [_metric_sentences(p), *_training_sentence(p), *_frame_sentences(rows, p, by_kind, activities, frames_per_activity),
             _empty_sentence(p)]
    if p.ground_truth:  # the paper's Table 4: ground truth from attention points
        parts.append("The ground truth of " + "; of ".join(f"{a} is {t}" for a, t in p.ground_truth.items())
                     + "; that of the other activities is masks drawn by people.")
    if by_kind[MODEL]:
        parts.append(_model_sentence(by_kind[MODEL], p))
    if by_kind[BASELINE]:
        parts.append(_baseline_sentence(by_kind[BASELINE], p))
    for study in p.human_maps:
        rows = [r for r in by_kind[HUMAN] if r.key in study.rows]
        if rows:
            parts.append(_study_sentences(study, rows, p))
    if not rows:
        parts.append("The report has no rows.")
    if depth := p.predicted_depth_text():
        parts.append(f"{depth}.")
    parts.append(_interval_sentence(p))
    parts.append(f"Scores were computed with {p.code_version or 'EgoNet Studio'}.")
    return " ".join(parts) + "\n"


def _metric_sentences(p: Provenance) -> str:
    t = p.thresholds
    name, _, what = METRIC_TITLES[p.metric].partition(": ")
    return (
        "We score each probability map against its frame's binary action-object mask with the maximum F-score (MF) "
        f"and average precision (AP) of Bertasius et al. (RSS 2017) [bertasius2017egonet], thresholding the map at T = {t} "
        f"thresholds t_k = k/{t + 1}, k = 1..{t}; a pixel is positive when its probability is at least t_k, and maps are "
        "never normalised. F = 2PR/(P+R) and AP = sum_k (R_k - R_{k+1}) P_k. "
        f"The convention is {name.lower()}{'' if name.lower() == p.metric else f' ({p.metric})'}: {what[0].lower() + what[1:]}."
    )


def _training_set(p: Provenance) -> str:
    """``"the 60 labelled frames of cooking and dining (cooking 30, dining 30)"``."""
    n = sum(p.training_frames.values())
    return (f"the {n} labelled frame{'' if n == 1 else 's'} of {_listed(list(p.trained_on))} "
            f"({_breakdown(p.training_frames)})")  # fmt: skip


def _training_sentence(p: Provenance) -> list[str]:
    """For a table of models scored where they were never trained (the paper's Tables 3 and 4): on what they learned;
    and what the columns are when they are recordings."""
    out = []
    if p.column_kind == "sequences":
        out.append("The table's columns are the recordings (sequences) of the activities, written activity / sequence, each "
                   "scored and resampled on its own where the rest of this paragraph says activity.")  # fmt: skip
    if not p.trained_on:
        return out
    return out + [f"Every model and learned baseline was trained on {_training_set(p)} only, with no frame held out, and is scored "
            "on the other activities, whose frames none of them saw (as in the paper's Tables 3 and 4)."]  # fmt: skip


def _frame_sentences(
    rows: Sequence[Row], p: Provenance, by_kind: Mapping[str, list[Row]], activities: Sequence[str], common: Mapping[str, int]
) -> list[str]:
    """Which frames each row stood on (the frame mode), and which activities each mean covers."""
    if not rows:
        return []
    out = []
    if p.frames == "shared":
        kept = {a: n for a, n in common.items() if n}
        had = [f"the {kind_name} had {_available(mine)}" for kind, kind_name in _KIND_NAMES.items() if (mine := by_kind[kind])]
        out.append(
            "Each activity is scored on its own, every row on the frames that all the rows scored in that activity have "
            f"(the shared frame mode): {frames_text(sum(kept.values()))} in all ({_breakdown(kept) or 'none'}); before that cut "
            f"{_listed(had)}."
        )
        dropped = [a for a, n in common.items() if not n]
        if dropped:
            verb = "has" if len(dropped) == 1 else "have"
            out.append(f"{_listed(dropped).capitalize()} {verb} no frame shared by all rows and {'is' if len(dropped) == 1 else 'are'} "
                       "left out of every row's mean.")  # fmt: skip
        out.append(f"The table reports each activity and the unweighted mean over the {count(len(kept), 'activity', 'activities')} with shared frames.")
    else:
        out.append(
            "Each row is scored on all the frames it has (the each frame mode), so rows stand on different frames: "
            "a column's best value is marked only among rows scored on the same frames."
        )
        partial = [r.name for r in rows if r.mean is not None and r.mean.activities < len(activities)]
        mean = ("The table reports each activity and the unweighted mean over the activities a row has frames in, of the "
                f"{count(len(activities), 'activity', 'activities')} in the table")  # fmt: skip
        if partial:
            whose = "one row's mean covers" if len(partial) == 1 else count(len(partial), "row") + "' means cover"
            mean += f"; {whose} fewer (marked *)"
        out.append(mean + ".")
    return out


_KIND_NAMES = {MODEL: "models", BASELINE: "baselines", HUMAN: "participants"}


def _scored_on(rows: Sequence[Row], p: Provenance, what: str) -> str:
    """``"on their held-out frames: 42 frames (...)"``; in the shared mode, on the shared frames among them."""
    if p.frames == "shared":
        return f"on the shared frames among {what}"
    return f"on {what}: {rows_frames(rows)}"


def _model_sentence(rows: list[Row], p: Provenance) -> str:
    """The runs by how they were split, each split's rows with the frames they were scored on."""

    def split(row: Row) -> str:
        return p.model_splits.get((row.members[0] if row.members else row).key, "")

    parts = []
    for how, meaning in SPLITS.items():
        mine = [r for r in rows if split(r) == how]
        n = sum(len(r.members) or 1 for r in mine)
        if n:
            parts.append(f"{count(n, 'training run')}, {meaning}, scored {_scored_on(mine, p, ('its' if n == 1 else 'their') + ' held-out frames')}")
    text = "Models: " + "; ".join(parts) + "."
    groups = sum(1 for r in rows if r.members)
    if groups:
        text += f" Runs that differ only in their seed are one row, their mean ({count(groups, 'such row')})."
    return text


def _baseline_sentence(rows: list[Row], p: Provenance) -> str:
    what = "the labelled frames" if p.frames == "shared" else "every labelled frame"
    text = f"Baselines: {_listed([r.name for r in rows])}, scored {_scored_on(rows, p, what)}"
    learned = [r.name for r in rows if is_trained(r.key.removeprefix("baseline:"))]
    if learned and p.trained_on:
        text += (f"; {_listed(learned)} {'was' if len(learned) == 1 else 'were'} fitted once, on the training activities' "
                 "labelled frames, as the models were, the others are not trained")
        if any(r.key == "baseline:aop" for r in rows):
            text += "; the action-object prior (AOP) is the mean ground-truth mask of those frames"
        return text + "."
    if learned:
        text += (f"; {_listed(learned)} {'was' if len(learned) == 1 else 'were'} fitted per fold under leave-one-activity-out "
                 "(a frame is mapped by a model fitted on the other activities' labelled frames only), the others are not trained")
    if any(r.key == "baseline:aop" for r in rows):
        text += "; the action-object prior (AOP) is the mean ground-truth mask of the other activities' labelled frames"
    return text + "."


def _study_sentences(study: HumanMaps, rows: list[Row], p: Provenance) -> str:
    name = study.study.split(" ", 2)[-1]
    out = [f"Human study {name}: {count(len(rows), 'participant')} scored"]
    left = []
    if study.pilots:
        left.append(f"{count(study.pilots, 'pilot participant')} left out")
    if study.excluded:
        left.append(f"{count(study.failed_checks, 'participant')} left out for failing a comprehension or attention check")
    elif study.failed_checks:
        left.append(f"{count(study.failed_checks, 'participant')} who failed a check kept")
    out[0] += f" ({'; '.join(left)})." if left else "."
    drawn = (f"Each was shown {frames_text(study.frames)} ({study.per_activity} from each of {count(study.activities, 'activity', 'activities')}, "
             f"drawn at random with seed {study.seed}, in {study.order} order)")  # fmt: skip
    unscored = [count(study.practice, "practice trial")] if study.practice else []
    if study.catch:
        unscored.append(count(study.catch, "attention-check (catch) trial"))
    verb = "is" if study.practice + study.catch == 1 else "are"
    out.append(drawn + (f", with {_listed(unscored)} that {verb} not scored." if unscored else "; no practice or catch trial."))
    unanswered = sum(r.unanswered or 0 for r in rows)
    if p.answered_only:
        out.append(f"Trials left unanswered are left out ({unanswered or 'none'} here).")
    else:
        out.append(f"A trial left unanswered (timed out, or not reached) counts as an empty map ({unanswered or 'none'} here).")
    out.append(
        f"Each click becomes a Gaussian with {study.sigma}; several clicks combine by their pixel-wise maximum, and the map is "
        f"projected onto {study.regions}, in place of the paper's MCG regions: each region takes the mean of the Gaussian over "
        "its pixels."
    )
    out.append(f"People are scored with MF only (AP says little about near-binary maps) {_scored_on(rows, p, 'the frames of their own trials')}.")
    return " ".join(out)


def _empty_sentence(p: Provenance) -> str:
    n = sum(p.empty_frames.values())
    if p.metric not in PER_FRAME_MEANS:
        if not n:
            return "No scored frame is without action-object pixels."
        return f"The {frames_text(n)} without action-object pixels count{'s' if n == 1 else ''} through {'its' if n == 1 else 'their'} false positives."
    what = EMPTY_TITLES[p.empty].replace("each scores", "scored")
    if not n:
        return f"No scored frame is without action-object pixels (such a frame would be {what})."
    return f"The {frames_text(n)} without action-object pixels {'is' if n == 1 else 'are'} {what}."


def _interval_sentence(p: Provenance) -> str:
    if not p.resamples:
        return "No confidence intervals were computed."
    return (
        "95% confidence intervals are bias-corrected and accelerated (BCa) bootstrap intervals over frames, resampled within "
        f"each activity, with B = {p.resamples} resamples (seed {p.seed}); below {MIN_FRAMES} frames in an activity a value "
        "is given without an interval (n too small). Paired comparisons resample both rows' shared frames alike, and their "
        f"two-sided p-values cannot go below 1/(B+1), reported as p {p.floor_text()}."
    )
