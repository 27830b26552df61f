"""What every part of the studies service shares: its error, the server's clock and the value checks.

Timing: the server is the authority. ``now()`` reads the app's
``STUDY_CLOCK`` (a callable returning an aware UTC datetime; tests freeze
it). ``LATE_GRACE_S`` is the one tolerance on every deadline (see
``app.services.studies.trials``).
"""

import re
from datetime import datetime
from typing import Any

from flask import current_app

from app.errors import Problem
from app.limits import TOKEN_REGEX
from app.models import utcnow

LATE_GRACE_S = 2.0
"""Seconds after a deadline during which an answer is still accepted (network latency)."""

TOKEN_PATTERN = re.compile(TOKEN_REGEX)
"""What a completion code, a condition name or a platform's id may hold (letters, digits, ``_ . -``)."""


class StudyProblem(Problem):
    """A study or participant request that cannot go ahead; ``field`` names the bad input."""


def now() -> datetime:
    """The server's time for study timing (the app's ``STUDY_CLOCK``, UTC)."""
    return current_app.config.get("STUDY_CLOCK", utcnow)()


def check_int(value: Any, name: str, low: int, high: int) -> int:
    """``value`` if it is a whole number in [low, high] (not a bool); else a StudyProblem naming ``name``."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise StudyProblem(f"{name} must be a whole number in [{low}, {high}]", field=name)
    return value


def check_number(value: Any, name: str, low: float, high: float) -> float:
    """``value`` as a float if it is a number in [low, high]; else a StudyProblem naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
        raise StudyProblem(f"{name} must be a number in [{low:g}, {high:g}]", field=name)
    return float(value)


def check_text(value: Any, name: str, *, max_len: int, min_len: int = 1) -> str:
    """``value`` stripped, with browsers' CRLF as LF, if it is a string of ``min_len``-``max_len`` characters."""
    if not isinstance(value, str):
        raise StudyProblem(f"{name} must be a string", field=name)
    value = value.replace("\r\n", "\n").strip()
    if not min_len <= len(value) <= max_len:
        raise StudyProblem(f"{name} must have {min_len}-{max_len} characters", field=name)
    return value


def check_token(value: Any, name: str) -> str:
    """A code or name of 1-64 letters, digits, ``_``, ``.`` or ``-``."""
    if not isinstance(value, str) or not TOKEN_PATTERN.fullmatch(value):
        raise StudyProblem(f"{name} must be 1-64 letters, digits, '_', '.' or '-'", field=name)
    return value


def check_bool(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise StudyProblem(f"{name} must be true or false", field=name)
    return value


def check_keys(value: Any, name: str, allowed: tuple[str, ...]) -> dict:
    """``value`` if it is an object whose keys are all in ``allowed``; the first unknown key is named."""
    if not isinstance(value, dict):
        raise StudyProblem(f"{name} must be an object", field=name)
    unknown = sorted(k for k in value if k not in allowed)
    if unknown:
        where = f"{name}." if name else ""
        raise StudyProblem(f"{where}{unknown[0]}: unknown key (known: {', '.join(allowed)})", field=f"{where}{unknown[0]}")
    return value
