"""Withdrawal: one participant's data deleted on request, their row kept as withdrawn.

What goes: their trials with the clicks and events (their soft masks are
made from the clicks, so none can be drawn again), the browser details the
page reported (the score cache's files of their maps go too: the view asks
scoring's cache, which imports this package, to forget them). What stays:
the row (code, platform id, condition, times, completion code), so the
counts of who arrived stay honest and a platform id that comes back is
recognised; it is deactivated, so its session ends and its place is freed,
and it says who withdrew it and when (also written to the log).
"""

from flask import current_app

from app.extensions import db
from app.models import User
from app.models.studies import Click, Participant, Trial, TrialEvent
from app.services.studies.common import StudyProblem, now


def withdraw(participant: Participant, *, by: User) -> int:
    """Delete ``participant``'s data (see above), marked as done by ``by`` now; returns the trials deleted.

    Raises:
        StudyProblem: 409 when they have already withdrawn.
    """
    if participant.withdrawn_at is not None:
        raise StudyProblem(f"{participant.label} has already withdrawn", status=409)
    trials = db.select(Trial.id).where(Trial.participant_id == participant.id)
    db.session.execute(db.delete(TrialEvent).where(TrialEvent.trial_id.in_(trials)))
    db.session.execute(db.delete(Click).where(Click.trial_id.in_(trials)))
    deleted = db.session.execute(db.delete(Trial).where(Trial.participant_id == participant.id)).rowcount
    db.session.expire(participant, ["trials"])
    participant.user.active = False
    participant.user.end_sessions()
    participant.user_agent, participant.environment, participant.external = None, None, {}
    participant.withdrawn_at, participant.withdrawn_by = now(), by
    db.session.commit()
    current_app.logger.warning("study %d: %s withdrawn by %s: %d trials deleted",
                               participant.study_id, participant.label, by.username, deleted)
    return deleted
