"""From per-frame counts to the table's rows: the frames each row is scored on, seed groups, intervals, comparisons.

* **Frames.** A row has frames per activity (its :class:`Source`'s
  statistics). With ``frames="shared"`` every row with frames in an
  activity is scored on the frames all of them have there (their
  intersection; a row left with none says so); with ``"each"`` on all its
  own frames.
* **Seeds.** Runs whose training differs only in its seed form a group row:
  each statistic is the mean over the runs (on the frames all of them have),
  with the standard deviation across them; the runs follow as their own rows.
* **Intervals.** Each (row, activity) is scored under the chosen convention
  once on its frames and once per bootstrap resample of them
  (``egonet.metrics.score_frames`` with the weights of
  ``egonet.metrics.Resampler``, shared by every row on the same frames);
  the mean over activities and the pooled ``all`` reuse those resamples.
* **Comparisons.** Two rows on the frames both have, with the same
  resamples: the paired differences, their intervals and p-values.
* **Frames without action-object pixels** are counted per activity
  (:func:`frames_without_truth`); when a per-frame mean leaves them out
  they are taken out of every source first (:func:`without_frames_without_truth`),
  so the n of each cell, the shared frames and the resamples are those of
  the frames averaged.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import reduce

import numpy as np

from app.errors import Problem
from app.services.scoring.cache import FrameStats
from app.services.scoring.cells import ALL, HUMAN, STATISTIC_LABELS, Cell, Curve, Difference, Row, frames_text, too_few
from app.services.scoring.provenance import Provenance
from app.services.scoring.table import Comparison
from egonet.metrics import DEFAULT_EMPTY, Estimate, FrameCounts, Resampler, curve_from_counts, f_scores, reduce_sums, weighted_sums

Values = dict[str, Estimate]
"""Each statistic's estimate: on the frames, on each resample, with each jackknife group left out."""


class ScoringProblem(Problem):
    """A score request that cannot go ahead; ``field`` names the bad input."""


@dataclass
class Source:
    """What one row is scored from, before any reduction.

    Attributes:
        key, name, kind, detail: As the :class:`~app.services.scoring.table.Row`'s.
        stats: The row's per-frame counts.
        unanswered: For a participant, trials without an answer.
        signature: For a run, everything its training depends on but the
            seed; runs with the same signature are grouped.
        label: What a group of such runs is called (the model's name).
        seed: For a run, its seed.
    """

    key: str
    name: str
    kind: str
    detail: str
    stats: FrameStats
    unanswered: int | None = None
    signature: str | None = None
    label: str = ""
    seed: int | None = None


def frames_without_truth(sources: Sequence[Source]) -> dict[str, int]:
    """Per activity (every activity a source has), how many distinct frames of the sources have no action-object pixel."""
    found: dict[str, set[int]] = {}
    for source in sources:
        none = source.stats.counts.positives == 0
        for activity in np.unique(source.stats.activities).tolist():
            found.setdefault(activity, set())
        for fid, activity in zip(source.stats.ids[none].tolist(), source.stats.activities[none].tolist(), strict=True):
            found[activity].add(fid)
    return {a: len(ids) for a, ids in sorted(found.items())}


def without_frames_without_truth(sources: Sequence[Source]) -> tuple[list[Source], list[str]]:
    """The sources without their frames that have no action-object pixel, and notes for the sources left with none."""
    kept, notes = [], []
    for source in sources:
        some = source.stats.counts.positives > 0
        if some.any():
            kept.append(replace(source, stats=source.stats.take(some)))
        else:
            notes.append(f"{source.name}: none of its frames has action-object pixels; all are left out.")
    return kept, notes


@dataclass
class _Entity:
    """A row to reduce: one source, or a group of sources that differ only in their seed."""

    key: str
    name: str
    kind: str
    detail: str
    members: list[Source]
    is_group: bool = False

    def frames(self) -> dict[str, np.ndarray]:
        """Frame ids per activity that every member has (increasing)."""
        own = [m.stats.by_activity() for m in self.members]
        common = set.intersection(*(set(f) for f in own))
        return {a: reduce(np.intersect1d, [f[a] for f in own]) for a in sorted(common)}


def _entities(sources: Sequence[Source]) -> list[_Entity]:
    """The rows in table order, runs of one signature folded into one group at the place of the first."""
    by_signature: dict[str, list[Source]] = {}
    for source in sources:
        if source.signature is not None:
            by_signature.setdefault(source.signature, []).append(source)
    out, placed = [], set()
    for source in sources:
        group = by_signature.get(source.signature) if source.signature is not None else None
        if group is None or len(group) < 2:
            out.append(_Entity(source.key, source.name, source.kind, source.detail, [source]))
        elif source.signature not in placed:
            placed.add(source.signature)
            runs = ", ".join(m.key.split(":", 1)[1] for m in group)
            seeds = ", ".join(str(m.seed) for m in group)
            out.append(
                _Entity(
                    key="seeds:" + runs.replace(" ", ""),
                    name=f"{source.label} ({len(group)} seeds)",
                    kind=source.kind,
                    detail=f"runs {runs} (seeds {seeds}), identical but for the seed",
                    members=group,
                    is_group=True,
                )
            )
    return out


def _fingerprint(parts: Sequence[object]) -> str:
    """A short digest of strings, tuples of strings and arrays (whole: an array's repr would shorten it)."""
    digest = hashlib.sha1()
    for part in parts:
        digest.update(part.tobytes() if isinstance(part, np.ndarray) else repr(part).encode())
    return digest.hexdigest()[:16]


@dataclass
class Scorer:
    """Scores sources on chosen frames under one convention, with the resamples of one :class:`Resampler`."""

    metric: str
    resampler: Resampler
    empty: str = DEFAULT_EMPTY
    _scored: dict[tuple[str, str], dict[str, Values]] = field(default_factory=dict, repr=False)

    @property
    def statistics(self) -> list[str]:
        return list(STATISTIC_LABELS[self.metric])

    def values(self, entity: _Entity, chosen: dict[str, np.ndarray]) -> list[dict[str, Values]]:
        """Each member's estimates per activity (activities with frames), and under :data:`ALL`.

        A source scored once on some frames is not scored again on them (a
        group's runs are both in the group and rows of their own).
        """
        chosen = {a: ids for a, ids in chosen.items() if ids.size}
        frames = _fingerprint([part for a, ids in chosen.items() for part in (a, ids)])
        out = []
        for member in entity.members:
            if (member.key, frames) not in self._scored:
                self._scored[member.key, frames] = self._member(member, chosen)
            out.append(self._scored[member.key, frames])
        return out

    def _member(self, member: Source, chosen: dict[str, np.ndarray]) -> dict[str, Values]:
        """One source's estimates. Its ``all`` reduces sums of the activities' weighted sums: no second pass over the frames.

        Rows of each activity's sums are the sample, the B resamples, then
        its jackknife groups; ``all`` adds the activities' sample and
        resample rows, and leaves each activity's groups out in turn from
        the total of the samples.
        """
        thresholds, b = member.stats.counts.thresholds, self.resampler.resamples
        sums = {
            a: weighted_sums(member.stats.select(ids), metric=self.metric, weights=self.resampler.weights(a, ids.size),
                             empty=self.empty, resampled_in_float32=True)
            for a, ids in chosen.items()
        }  # fmt: skip
        out: dict[str, Values] = {}
        for a, s in sums.items():
            reduced = reduce_sums(s, metric=self.metric, thresholds=thresholds, resampled_in_float32=True)
            out[a] = {k: self.resampler.estimate(v) for k, v in reduced.items()}
        if sums:
            head = sum(part[: 1 + b] for part in sums.values())
            jack = [head[0] - part[0] + part[1 + b :] for part in sums.values()]
            reduced = reduce_sums(np.vstack([head, *jack]), metric=self.metric, thresholds=thresholds, resampled_in_float32=True)
            splits = np.cumsum([1 + b] + [len(j) for j in jack])[:-1]
            out[ALL] = {}
            for k, v in reduced.items():
                parts = np.split(v, splits)
                out[ALL][k] = Estimate(float(parts[0][0]), parts[0][1:], tuple(parts[1:]))
        return out


def _mean(values: Sequence[Values]) -> Values:
    """The element-wise mean of several members' estimates (a group of seeds)."""
    return {s: Estimate.mean([v[s] for v in values]) for s in values[0]}


def _stratified(values: Sequence[Values]) -> Values:
    """The mean over activities of one member's per-activity estimates."""
    return {s: Estimate.stratified_mean([v[s] for v in values]) for s in values[0]}


def _cell(
    scorer: Scorer,
    members: list[Values] | None,
    *,
    hide: set[str],
    n_frames: int,
    available: int,
    key: str,
    activities: int = 1,
    few: bool = False,
) -> Cell:
    """A cell from its members' values (one member, or a group's runs); None: no frames scored. ``few``: n too small, no interval."""
    if not members:
        empty = {s: None for s in scorer.statistics}
        return Cell(n_frames=0, values=empty, ci=empty, frames_available=available, frames_key=key, activities=activities)
    values = _mean(members)
    shown = [s for s in scorer.statistics if s not in hide]
    sd = None
    if len(members) > 1:
        sd = {s: (float(np.std([m[s].value for m in members], ddof=1)) if s in shown else None) for s in scorer.statistics}
    return Cell(
        n_frames=n_frames,
        values={s: values[s].value if s in shown else None for s in scorer.statistics},
        ci={s: values[s].interval() if s in shown and not few else None for s in scorer.statistics},
        sd=sd,
        frames_available=available,
        frames_key=key,
        activities=activities,
        too_few=few,
    )


def _curves(source: Source, chosen: dict[str, np.ndarray]) -> dict:
    """The source's pooled precision-recall curve per activity and over all its chosen frames."""
    parts = {a: source.stats.select(ids) for a, ids in chosen.items() if ids.size}
    if parts:
        parts[ALL] = FrameCounts.concat(list(parts.values()), thresholds=source.stats.counts.thresholds)
    curves = {}
    for key, counts in parts.items():
        precision, recall = curve_from_counts(counts.pooled())
        best = int(np.argmax(f_scores(precision, recall)))
        curves[key] = Curve(tuple(np.round(precision, 5).tolist()), tuple(np.round(recall, 5).tolist()), best)
    return curves


def _row(scorer: Scorer, entity: _Entity, chosen: dict[str, np.ndarray], available: dict[str, np.ndarray]) -> Row:
    hide = {"ap"} if entity.kind == HUMAN else set()
    per_member = scorer.values(entity, chosen)
    cells = {}
    for activity, ids in chosen.items():
        cells[activity] = _cell(
            scorer,
            [m[activity] for m in per_member if activity in m],
            hide=hide,
            n_frames=int(ids.size),
            available=int(available[activity].size),
            key=_fingerprint([activity, ids]),
            few=bool(ids.size) and too_few(int(ids.size)),
        )
    scored = [a for a, ids in chosen.items() if ids.size]
    mean = overall = None
    if scored:
        n = sum(int(chosen[a].size) for a in scored)
        key = _fingerprint([(a, cells[a].frames_key) for a in scored])
        common = {"hide": hide, "n_frames": n, "available": sum(int(f.size) for f in available.values()), "key": key,
                  "few": too_few(*(int(chosen[a].size) for a in scored))}  # fmt: skip
        mean = _cell(scorer, [_stratified([m[a] for a in scored]) for m in per_member], activities=len(scored), **common)
        overall = _cell(scorer, [m[ALL] for m in per_member], activities=len(scored), **common)
    single = entity.members[0]
    row = Row(
        key=entity.key,
        name=entity.name,
        kind=entity.kind,
        detail=entity.detail,
        cells=cells,
        mean=mean,
        overall=overall,
        curves={} if entity.is_group else _curves(single, chosen),
        unanswered=None if entity.is_group else single.unanswered,
        seed=None if entity.is_group else single.seed,
    )
    if entity.is_group:
        for member in entity.members:
            alone = _Entity(member.key, member.name, member.kind, member.detail, [member])
            member_row = _row(scorer, alone, chosen, available)
            member_row.group = entity.key
            row.members.append(member_row)
    return row


def build_rows(sources: Sequence[Source], *, frames: str, scorer: Scorer) -> tuple[list[Row], list[str], list[str]]:
    """The rows of these sources, scored on the chosen frames.

    Args:
        sources: In table order.
        frames: ``"shared"`` or ``"each"``.
        scorer: The convention and the resamples.

    Returns:
        ``(rows, activities, notes)``: activities are the columns (every
        activity some row has frames in); notes say where the shared frames
        are fewer than a row has.
    """
    entities = _entities(sources)
    available = {e.key: e.frames() for e in entities}
    activities = sorted({a for f in available.values() for a in f})
    chosen = {key: dict(f) for key, f in available.items()}
    notes = []
    if frames == "shared":
        for activity in activities:
            having = [key for key, f in available.items() if activity in f]
            common = reduce(np.intersect1d, [available[key][activity] for key in having])
            most = max(available[key][activity].size for key in having)
            for key in having:
                chosen[key][activity] = common
            if common.size < most:
                notes.append(
                    f"{activity}: {frames_text(common.size)} shared by the {len(having)} rows scored there (a row has up to {most})."
                )
    rows = [_row(scorer, e, chosen[e.key], available[e.key]) for e in entities]
    return rows, activities, notes


def compare(sources: Sequence[Source], key_a: str, key_b: str, *, scorer: Scorer, provenance: Provenance) -> Comparison:
    """Row ``key_a`` minus row ``key_b`` on the frames both have, per activity and for the mean over activities.

    Raises:
        ScoringProblem: naming ``compare`` when a key is not a row of the
            table, or the two rows share no frame.
    """
    entities = {}
    for entity in _entities(sources):
        entities[entity.key] = entity
        if entity.is_group:
            entities |= {m.key: _Entity(m.key, m.name, m.kind, m.detail, [m]) for m in entity.members}
    for key in (key_a, key_b):
        if key not in entities:
            known = ", ".join(entities) or "none"
            raise ScoringProblem(f"compare: there is no row {key!r} in this table (rows: {known})", field="compare")
    a, b = entities[key_a], entities[key_b]
    hide = {"ap"} if HUMAN in (a.kind, b.kind) else set()
    statistics = [s for s in scorer.statistics if s not in hide]
    frames_a, frames_b = a.frames(), b.frames()
    shared = {act: np.intersect1d(frames_a[act], frames_b[act]) for act in sorted(set(frames_a) & set(frames_b))}
    shared = {act: ids for act, ids in shared.items() if ids.size}
    if not shared:
        raise ScoringProblem(f"compare: {a.name} and {b.name} have no frame in common", field="compare")
    differences = {}
    for act, ids in shared.items():
        va, vb = (_mean([v[act] for v in scorer.values(e, {act: ids})]) for e in (a, b))
        differences[act] = {s: va[s] - vb[s] for s in statistics}

    def summary(d: Estimate, *sizes: int) -> Difference:
        if too_few(*sizes):
            return Difference(d.value, None, None, sum(sizes), too_few=True)
        return Difference(d.value, d.interval(), d.p_value(), sum(sizes))

    sizes = [int(ids.size) for ids in shared.values()]
    return Comparison(
        a=(a.key, a.name),
        b=(b.key, b.name),
        statistics=tuple(statistics),
        activities={act: {s: summary(d[s], int(shared[act].size)) for s in statistics} for act, d in differences.items()},
        mean={s: summary(Estimate.stratified_mean([d[s] for d in differences.values()]), *sizes) for s in statistics},
        provenance=replace(provenance, paired=True),
    )
