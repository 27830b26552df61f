"""What every part of the studies service shares: its error and the server's clock.

Timing: the server is the authority. ``now()`` reads the app's
``STUDY_CLOCK`` (a callable returning an aware UTC datetime; tests freeze
it). ``LATE_GRACE_S`` is the one tolerance on every deadline (see
``app.services.studies.session``).
"""

from datetime import datetime

from flask import current_app

from app.errors import Problem
from app.models import utcnow

LATE_GRACE_S = 2.0
"""Seconds after a deadline during which an answer is still accepted (network latency)."""


class StudyProblem(Problem):
    """A study or participant request that cannot go ahead; ``field`` names the bad input."""


def now() -> datetime:
    """The server's time for study timing (the app's ``STUDY_CLOCK``, UTC)."""
    return current_app.config.get("STUDY_CLOCK", utcnow)()
