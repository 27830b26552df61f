"""Quality checks: where clicks fall (answer regions, ground truth), who passed the checks, which code they get.

A catch trial's answer region is its box (native pixels, ``[x0, y0, x1,
y1]``, inclusive) or the frame's ground-truth mask; a click is in a mask
when the pixel it falls on (rounded to the nearest centre) is. The trial
passes when one of its clicks is in the region (``Trial.hit``, stored when
the answer is recorded); a catch trial closed without a hit (answered
"none", missed, ran out of time) fails.

A participant's checks: the comprehension questions (passed, failed: they
were screened out, or none asked) and the catch trials. ``passed`` is False
once any check failed, True once every check passed, None until then.
"""

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from sqlalchemy import case, func

from app.extensions import db
from app.models import Frame
from app.models.studies import EndReason, FrameKind, Participant, StudyFrame, Trial
from app.services import ground_truth


def truth_mask(frame: Frame) -> np.ndarray | None:
    """The frame's ground-truth mask, bool (H, W), or None without one."""
    annotation = ground_truth.ground_truths([frame.id]).get(frame.id)
    return ground_truth.mask_of(annotation) if annotation is not None else None


def inside_mask(mask: np.ndarray, points: Iterable[tuple[float, float]]) -> list[bool]:
    """For each (x, y) in native pixels (x column, y row), whether it falls on a true pixel of ``mask`` (H, W)."""
    h, w = mask.shape
    out = []
    for x, y in points:
        row, col = min(max(round(y), 0), h - 1), min(max(round(x), 0), w - 1)
        out.append(bool(mask[row, col]))
    return out


def inside_box(box: Sequence[float], points: Iterable[tuple[float, float]]) -> list[bool]:
    x0, y0, x1, y1 = box
    return [x0 <= x <= x1 and y0 <= y <= y1 for x, y in points]


def catch_hit(study_frame: StudyFrame, points: Sequence[tuple[float, float]]) -> bool:
    """Whether one of the clicks is in the catch frame's answer region (False without clicks)."""
    if not points:
        return False
    if study_frame.region and "box" in study_frame.region:
        return any(inside_box(study_frame.region["box"], points))
    mask = truth_mask(study_frame.frame)
    return mask is not None and any(inside_mask(mask, points))


@dataclass
class Checks:
    """A participant's checks: comprehension (``passed``, ``failed``, ``pending`` or ``none``) and catch trials."""

    comprehension: str
    catch_total: int = 0
    catch_passed: int = 0
    catch_failed: int = 0

    @property
    def asked(self) -> bool:
        """Whether the study has any check for this participant (questions or catch trials)."""
        return self.comprehension != "none" or self.catch_total > 0

    @property
    def passed(self) -> bool | None:
        if self.comprehension == "failed" or self.catch_failed:
            return False
        if self.comprehension in ("passed", "none") and self.catch_passed == self.catch_total:
            return True
        return None

    def as_dict(self) -> dict:
        return {
            "passed": self.passed,
            "comprehension": self.comprehension,
            "catch_trials": {"total": self.catch_total, "passed": self.catch_passed, "failed": self.catch_failed},
        }


def _comprehension(participant: Participant) -> str:
    if not participant.study.comprehension:
        return "none"
    if participant.comprehension_passed_at is not None:
        return "passed"
    return "failed" if participant.end_reason is EndReason.SCREENED_OUT else "pending"


def checks_of(participants: Iterable[Participant]) -> dict[int, Checks]:
    """Each participant's checks, by participant id (one query for the catch trials of them all)."""
    people = list(participants)
    rows = db.session.execute(
        db.select(
            Trial.participant_id,
            func.count(),
            func.sum(case((Trial.hit.is_(True), 1), else_=0)),
            func.sum(case((Trial.outcome.is_not(None) & Trial.hit.is_not(True), 1), else_=0)),
        )
        .join(StudyFrame, Trial.study_frame)
        .where(Trial.participant_id.in_([p.id for p in people]), StudyFrame.kind == FrameKind.CATCH)
        .group_by(Trial.participant_id)
    ).all()
    catch = {pid: (total, passed or 0, failed or 0) for pid, total, passed, failed in rows}
    return {p.id: Checks(_comprehension(p), *catch.get(p.id, (0, 0, 0))) for p in people}


def completion_code(participant: Participant, reason: EndReason) -> str | None:
    """The code a participant gets at the end: the study's code when they completed with no failed check,
    else its ``failed_code`` when it has one; none after declining or when the study has no code."""
    study = participant.study
    if reason is EndReason.DECLINED or not study.completion_code:
        return None
    clean = reason is EndReason.COMPLETED and checks_of([participant])[participant.id].passed is not False
    return study.completion_code if clean or not study.failed_code else study.failed_code


def grade(questions: list[dict], answers: dict[int, int]) -> bool:
    """Whether every question got its right option (``answers``: question index -> option index)."""
    return all(answers.get(i) == q["answer"] for i, q in enumerate(questions))
