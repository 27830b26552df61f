"""Where the scored maps come from: ground truth, and each source's statistics per activity.

Ground truth is each frame's finished annotation (``app.services.ground_truth``),
loaded once per report as a :class:`Truth`. The three sources stream their
maps, one at a time, into per-frame counts (``cache.FrameStats``):

* a completed training run: its held-out predictions (``app.services.training``);
  the authors' released model, never trained on ours, holds every frame out;
* a baseline (``egonet.baselines``) on every labelled frame: a learned one
  (AOP, Judd, FP-MCG, salObj+depth, Handled+Viewed-Obj's hand detector) with
  the model of the frame's leave-one-activity-out fold, fitted without the
  frame's activity (``fitting``); GBVS, the centre prior and saliency as they are;
* a participant: the click soft masks of the frames they answered
  (``app.services.studies``), and an empty map for each trial they did not
  answer (expired, or never reached once their session is over), flagged
  so that a report can leave those out.

Each returns ``({statistics name: Stats}, notes)``, what ``cache`` stores.
"""

from __future__ import annotations

import hashlib
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from app.extensions import db
from app.models import Activity, Annotation, Frame, Instance, is_hand
from app.models import Sequence as FrameSequence
from app.models.studies import FrameKind, Outcome, Participant, StudyFrame, Trial
from app.models.training import TrainingRun
from app.services import ground_truth, media, training
from app.services import studies as studies_service
from app.services.scoring.cache import Stats, StatsBuilder
from egonet import io
from app.services.scoring import fitting
from egonet.baselines import BASELINES, build_baseline, is_trained
from egonet.metrics import count_stats
from egonet.network.builders import PAPER_NAMES

def baseline_rows() -> list[tuple[str, bool]]:
    """Every baseline's name (the paper's name of its method) and whether it is learned (fitted per fold), in the table's order."""
    return [(baseline_name(key), is_trained(key)) for key in BASELINES]


def baseline_name(key: str, truth: Truth | None = None) -> str:
    """The row name of baseline ``key``: the paper's name of its method; with ``truth``, Handled+Viewed-Obj's says where its hands come from."""
    name = BASELINES[key].name
    return f"{name} (hands: {_hands_of(truth, build_baseline(key).min_frames)})" if key == "handled" and truth else name


def _hands_of(truth: Truth, min_frames: int) -> str:
    """What the handled row's folds detect hands with: a model learned on n frames with ``hand`` instances, or skin colour.

    Counted from the labels (a fold learns from the other activities' frames
    with a hand instance, when it has ``min_frames`` of them; else skin colour).
    """
    per_activity = Counter(truth.activity[fid] for fid, labels in truth.labels.items() if any(map(is_hand, labels)))
    total = sum(per_activity.values())
    if truth.trained_on:  # one fit, on the training activities
        folds = [sum(per_activity[a] for a in truth.trained_on)]
    else:
        folds = [total - per_activity[a] for a in truth.by_activity()] if len(truth.by_activity()) > 1 else [0]
    learned = sorted(n for n in folds if n >= min_frames)
    if not learned:
        return "skin colour"
    frames = f"{learned[0]}" if learned[0] == learned[-1] else f"{learned[0]}-{learned[-1]}"
    described = f"learned, {frames} frames" + (" a fold" if len(folds) > 1 else "")
    skin = len(folds) - len(learned)
    return described + (f"; skin colour in {skin} fold{'s' if skin > 1 else ''}" if skin else "")


Scored = tuple[dict[str, Stats], list[str]]
"""A source's statistics by name ("" for a single row, else the baseline's key) and its notes."""


# --------------------------------------------------------------------------
# Ground truth, loaded once per report


@dataclass
class Truth:
    """The labelled frames, their ground-truth annotations and activities, and fingerprints of them.

    ``entries`` holds each frame's fingerprint entry (its media, its
    annotation's id, version, mask and update time, its instances' labels
    and masks): a fold's training frames are fingerprinted from theirs.
    """

    frames: list[Frame]
    annotations: dict[int, Annotation]
    activity: dict[int, str]  # frame id -> activity name
    entries: dict[int, str]
    fingerprint: str
    labels: dict[int, list[str]] = field(default_factory=dict)  # frame id -> its instances' labels
    trained_on: tuple[str, ...] = ()  # a table of models trained on these activities: they are not scored
    sequence: dict[int, str] = field(default_factory=dict)  # frame id -> its sequence (recording, video) name
    columns: str = "activities"  # the table's columns: "activities", or "sequences" (each activity's recordings)

    def column(self, frame_id: int) -> str:
        """The table column a frame is scored in: its activity, or ``"activity / sequence"``."""
        activity = self.activity[frame_id]
        return f"{activity} / {self.sequence[frame_id]}" if self.columns == "sequences" else activity

    def mask(self, frame_id: int) -> np.ndarray | None:
        annotation = self.annotations.get(frame_id)
        return ground_truth.mask_of(annotation) if annotation is not None else None

    def scored(self, frame_id: int) -> bool:
        """Whether the frame is one of the table's (not of the training activities of a table trained on some)."""
        return self.activity.get(frame_id) not in self.trained_on

    def by_activity(self) -> dict[str, list[Frame]]:
        """The frames of each scored activity, in the frames' order."""
        out: dict[str, list[Frame]] = defaultdict(list)
        for frame in self.frames:
            if self.scored(frame.id):
                out[self.activity[frame.id]].append(frame)
        return dict(out)

    def training_frames(self, held_out: str) -> list[Frame]:
        """The frames that the learned baselines mapping ``held_out`` are fitted on.

        Leave-one-activity-out: every other activity's. In a table trained on
        some activities: theirs, whichever activity is scored.
        """
        if self.trained_on:
            return [f for f in self.frames if self.activity[f.id] in self.trained_on]
        return [f for f in self.frames if self.activity[f.id] != held_out]

    def digest(self, frame_ids: Iterable[int]) -> str:
        """A fingerprint of these frames and their ground truth (a fold's training frames)."""
        digest = hashlib.sha256()
        for fid in sorted(frame_ids):
            digest.update(self.entries[fid].encode())
        return digest.hexdigest()


def load_truth(trained_on: Sequence[str] = (), columns: str = "activities") -> Truth:
    """Every labelled frame's ground truth; the fingerprint changes whenever an annotation does.

    With ``trained_on`` (a table of models trained on those activities), the
    frames of those activities are training frames, never scored, and the
    fingerprint (every cache key of the report) says so. ``columns="sequences"``
    scores each recording (sequence) of an activity as a column of its own
    (a dataset of videos imported as one activity; the learned baselines'
    folds stay by activity).
    """
    frames = ground_truth.labelled_frames()
    ids = [f.id for f in frames]
    annotations: dict[int, Annotation] = {}
    instances: dict[int, list[str]] = defaultdict(list)
    labels: dict[int, list[str]] = defaultdict(list)
    for start in range(0, len(ids), 5000):  # keep IN lists well under SQLite's variable limit
        chunk = ground_truth.ground_truths(ids[start : start + 5000])
        annotations.update(chunk)
        for aid, label, path in db.session.execute(
            db.select(Instance.annotation_id, Instance.label, Instance.mask_path)
            .where(Instance.annotation_id.in_([a.id for a in chunk.values()]))
            .order_by(Instance.annotation_id, Instance.position)
        ):
            instances[aid].append(f"{label}={path}")
            labels[aid].append(label or "")
    found = (
        db.session.execute(
            db.select(Frame.id, Activity.name, FrameSequence.name)
            .select_from(Frame)
            .join(FrameSequence, Frame.sequence)
            .join(Activity, FrameSequence.activity)
            .where(Frame.id.in_(db.select(Annotation.frame_id)))
        ).all()
    )
    names = {fid: activity for fid, activity, _ in found}
    sequences = {fid: sequence for fid, _, sequence in found}
    media_of = {f.id: f"{f.rgb_path}|{f.dhg_path}" for f in frames}
    entries = {}
    for fid, a in annotations.items():
        entries[fid] = (f"{fid}:{media_of.get(fid)}:{a.id}:{a.version}:{a.mask_path}:{a.updated_at.isoformat()}:"
                        f"{','.join(instances[a.id])};")  # fmt: skip
    truth = Truth(frames, annotations, {f.id: names[f.id] for f in frames}, entries, "",
                  {fid: labels[a.id] for fid, a in annotations.items()}, tuple(sorted(trained_on)),
                  {f.id: sequences[f.id] for f in frames}, columns)  # fmt: skip
    truth.fingerprint = truth.digest(entries)
    if truth.trained_on or columns != "activities":
        truth.fingerprint = hashlib.sha256(f"{truth.fingerprint}|trained on|{truth.trained_on!r}|{columns}".encode()).hexdigest()
    return truth


# --------------------------------------------------------------------------
# The three sources


def _accumulate(
    pairs: Iterable[tuple[Frame, np.ndarray]], truth: Truth, thresholds: int, on_progress: Callable[[int], None]
) -> tuple[StatsBuilder, int]:
    """Count (frame, map) pairs; return the frames' counts and how many frames had no ground truth."""
    stats = StatsBuilder(thresholds)
    missing = 0
    for frame, prob in pairs:
        if not truth.scored(frame.id):  # a training activity's frame: not a column of this table
            continue
        mask = truth.mask(frame.id)
        if mask is None:
            missing += 1
            continue
        stats.add(frame.id, truth.column(frame.id), count_stats(prob, mask, thresholds=thresholds, name=f"prob of frame {frame.id}"))
        on_progress(1)
    return stats, missing


def gone(n: int, what: str = "") -> str:
    """The note for frames whose ground truth went away: ``"1 frame no longer has a ground truth and was left out."``."""
    one = n == 1
    return f"{n} {what}frame{'' if one else 's'} no longer ha{'s' if one else 've'} a ground truth and {'was' if one else 'were'} left out."


def model_label(run: TrainingRun) -> str:
    """A run's model as the paper names it (EgoNet, DeepLab-RGB, DeepLab-DHG), else the variant's own name."""
    return PAPER_NAMES.get(run.model_name, run.model_name)


def run_row_name(run: TrainingRun) -> str:
    """A run's row: its model, or "released model" for the authors' weights (scored on every frame it predicted).

    An object-class run (DeepLab-Obj) says how many classes its folds learned
    ("DeepLab-Obj, 12 classes" or "10-12 classes" when the folds differ).
    """
    if run.folds == "released":
        return f"released model, {run.config.get('released', {}).get('release', '').upper()} (run {run.id})"
    counts = sorted({c.metrics["classes"] for c in run.checkpoints if "classes" in (c.metrics or {})})
    if counts:
        n = str(counts[0]) if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
        return f"{model_label(run)}, {n} classes (run {run.id})"
    return f"{model_label(run)} (run {run.id})"


def run_stats(run: TrainingRun, truth: Truth, thresholds: int, on_progress: Callable[[int], None]) -> Scored:
    """Score a run's held-out predictions (frames without a ground truth any more become a note)."""
    stats, missing = _accumulate(training.held_out_predictions(run), truth, thresholds, on_progress)
    notes = [f"run {run.id}: {gone(missing, 'held-out ')}"] if missing else []
    return {"": stats.build()}, notes


def human_participants(
    study_ids: Iterable[int], *, exclude_failed_checks: bool = False, by_condition: bool = False
) -> list[tuple[Participant, str | None]]:
    """The participants scored as human rows, each with the condition its row is split by (None when not split).

    Only the timed part is scored (``participant_soft_masks`` leaves practice
    and catch trials out); ``exclude_failed_checks`` leaves out whoever failed
    a comprehension or attention check; ``by_condition`` orders the rows by
    condition within each study and names it.
    """
    people = studies_service.study_participants(study_ids, exclude_failed_checks=exclude_failed_checks)
    if not by_condition:
        return [(p, None) for p in people]
    rows = [(p, studies_service.condition_name(p) or "") for p in people]
    return sorted(rows, key=lambda row: (row[0].study_id, row[1], row[0].number))


def unanswered_frames(participant: Participant, *, session_over: bool) -> list[Frame]:
    """The frames of a participant's trials without an answer: expired ones, and once the session is over every trial left."""
    unanswered = Trial.outcome == Outcome.EXPIRED
    if session_over:
        unanswered |= Trial.outcome.is_(None)
    return list(
        db.session.execute(
            db.select(Frame)
            .join(StudyFrame, StudyFrame.frame_id == Frame.id)
            .join(Trial, Trial.study_frame_id == StudyFrame.id)
            .where(Trial.participant_id == participant.id, StudyFrame.kind == FrameKind.MAIN, unanswered)
            .order_by(Trial.position)
        ).scalars()
    )


def participant_stats(
    participant: Participant, truth: Truth, thresholds: int, on_progress: Callable[[int], None], *, session_over: bool
) -> Scored:
    """Score a participant's soft masks of the frames they answered, and an empty map for each trial they did not answer."""
    stats, missing = _accumulate(studies_service.participant_soft_masks(participant), truth, thresholds, on_progress)
    for frame in unanswered_frames(participant, session_over=session_over):
        mask = truth.mask(frame.id)
        if mask is None:
            missing += 1
            continue
        empty = np.zeros(mask.shape, np.float32)
        stats.add(frame.id, truth.column(frame.id), count_stats(empty, mask, thresholds=thresholds), answered=False)
        on_progress(1)
    label = f"{participant.label} of study {participant.study_id}"
    notes = [f"{label}: {gone(missing)}"] if missing else []
    return {"": stats.build()}, notes


def baseline_maps(key: str, truth: Truth, notes: list[str], on_progress: Callable[[int], None]) -> Iterator[tuple[Frame, np.ndarray]]:
    """Baseline ``key``'s map of every scored labelled frame, activity by activity.

    A learned baseline maps the frames of activity A with the model of A's
    fold, fitted on the other activities only (``fitting``: cached, fitted
    first when not), or in a table trained on some activities with the one
    model fitted on those; it is given the frame's DHG, the others only its colour.
    """
    trained = is_trained(key)
    folds = fitting.fit_missing(key, truth, on_frame=lambda: on_progress(1)) if trained else {}
    shared = None if trained else build_baseline(key)
    for activity, frames in truth.by_activity().items():
        predictor = folds.get(activity) if trained else shared
        if predictor is None:
            where = (f"no training activity ({', '.join(truth.trained_on)}) has labelled frames to fit it on" if truth.trained_on
                     else f"no other activity has labelled frames to fit the fold of {activity}")
            notes.append(f"{BASELINES[key].name}: {where}.")
            continue
        for frame in frames:
            rgb = io.read_image(media.local_path(frame.rgb_path))
            dhg = io.read_dhg(media.local_path(frame.dhg_path)) if trained and frame.dhg_path else None
            yield frame, predictor.predict(rgb, dhg)


def baseline_stats(key: str, truth: Truth, thresholds: int, on_progress: Callable[[int], None]) -> Scored:
    """Score baseline ``key`` on every labelled frame (a learned one fitted per leave-one-activity-out fold)."""
    notes: list[str] = []
    stats, _ = _accumulate(baseline_maps(key, truth, notes, on_progress), truth, thresholds, on_progress)
    return {"": stats.build()}, notes
