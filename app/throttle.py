"""Throttling of guesses: passwords (Flask-Limiter) and study entry (counted in the database).

Log-in: Flask-Limiter counts failed attempts per key (the account and the
client's address) in a fixed window that starts at the first failure. Only
failures count (``deduct_when=failed``), so people who type their password
right are never slowed down, and a success forgets the failures before it
(``forgive``): the limit is on failures in a row. Once ``RATELIMIT_FAILURES``
failures are reached within ``RATELIMIT_WINDOW``, every attempt for that key
is answered 429 with ``Retry-After`` until the window ends, a correct
password included. Storage: in memory (per server process) by default;
Redis when ``RATELIMIT_STORAGE_URI`` is a ``redis://`` URL, or, when it is
unset and the queue's URL (``QUEUE_URL``, from ``EGONET_QUEUE_URL``) is
one, that Redis (so several gunicorn processes and machines share the
counts).

Study entry (``entry_attempts``): wrong codes and unknown links count per
study and address (``EntryFailures`` rows, the study being the one the
attempt names: the entry form's ``?study=``, a link's study; none for the
shared form and unknown links), ``RATELIMIT_ENTRY_FAILURES`` (200) in
``RATELIMIT_WINDOW``: a class behind one university address mistypes a
code now and then, and 200 wrong guesses per window at 31**8 possible codes
find nothing. Successful entries never count. The rows are in the database
so that every server process shares them and staff can see and clear a
lock on the study's page.

The limiter is one object for the process (views are decorated with it at
import). Each ``create_app`` gives it that app's switch, limits and a fresh
store; a few Flask-Limiter settings (``RATELIMIT_KEY_PREFIX``,
``RATELIMIT_STRATEGY``) keep the first app's value, which only matters to a
process that makes several apps (the tests).
"""

import functools
import math
import time
from collections.abc import Callable
from datetime import timedelta

from flask import Flask, Response, current_app, request
from flask_limiter import Limiter
from flask_limiter.util import get_remote_address
from limits import parse

from app.errors import Problem, error_response
from app.extensions import db
from app.models.base import utcnow
from app.models.studies import EntryFailures, Participant, Study

limiter = Limiter(key_func=get_remote_address, default_limits=[], headers_enabled=True)


def storage_uri(app: Flask) -> str:
    configured = app.config.get("RATELIMIT_STORAGE_URI")
    if configured:
        return configured
    queue = app.config.get("QUEUE_URL") or ""
    return queue if queue.startswith(("redis://", "rediss://")) else "memory://"


def init_app(app: Flask) -> None:
    # Explicit, because Flask-Limiter keeps the last app's value on its one
    # object: an app created with the limiter off must not switch it off for
    # the next one.
    app.config.setdefault("RATELIMIT_ENABLED", True)
    app.config.setdefault("RATELIMIT_FAILURES", 20)
    app.config.setdefault("RATELIMIT_WINDOW", "15 minutes")
    app.config.setdefault("RATELIMIT_ENTRY_FAILURES", 200)
    app.config["RATELIMIT_STORAGE_URI"] = storage_uri(app)
    app.config.setdefault("RATELIMIT_HEADERS_ENABLED", True)
    limiter.init_app(app)


def failures_limit() -> str:
    """The limit string from the config, e.g. ``20 per 15 minutes``."""
    return f"{current_app.config['RATELIMIT_FAILURES']} per {current_app.config['RATELIMIT_WINDOW']}"


def failed(response: Response) -> bool:
    """A refused attempt: a wrong password or code (401), or an unknown link (404)."""
    return response.status_code in (401, 404)


def forgive() -> None:
    """Forget the failures counted so far for this request's keys: a success ends a run of failures.

    Call it in a view once the attempt succeeded (no-op when the limiter is off).
    """
    for limit in limiter.current_limits:
        limiter.limiter.clear(limit.limit, *limit.request_args)


def address() -> str:
    return get_remote_address() or request.remote_addr or "unknown"


def too_many_attempts() -> str:
    """The message of the 429: when to try again, in words (``Retry-After`` has the seconds)."""
    limit = limiter.current_limit
    if limit is None:
        return "Too many failed attempts. Wait a while, then try again."
    return _try_again(max(1, math.ceil(limit.reset_at - time.time())))


def _try_again(wait: int) -> str:
    when = f"{wait} seconds" if wait < 90 else f"{round(wait / 60)} minutes"
    return f"Too many failed attempts. Try again in {when}."


def window_s() -> int:
    """``RATELIMIT_WINDOW`` in seconds."""
    return parse(f"1 per {current_app.config['RATELIMIT_WINDOW']}").get_expiry()


def _of_study(study_id: int | None):
    return EntryFailures.study_id.is_(None) if study_id is None else EntryFailures.study_id == study_id


def _counting():
    """The counts whose window has not ended."""
    return db.select(EntryFailures).where(EntryFailures.since > utcnow() - timedelta(seconds=window_s()))


def _current(study_id: int | None) -> EntryFailures | None:
    """This address's count for the study (None: the shared one) in its window."""
    return db.session.execute(_counting().where(_of_study(study_id), EntryFailures.address == address())).scalars().first()


def locked_s(row: EntryFailures) -> int:
    """Seconds until ``row``'s lock ends (0: not locked)."""
    if row.failures < current_app.config["RATELIMIT_ENTRY_FAILURES"]:
        return 0
    return max(0, math.ceil((row.since + timedelta(seconds=window_s()) - utcnow()).total_seconds()))


def entry_study() -> int | None:
    """The study an entry attempt names: the code form's ``?study=``, a link's or the open link's study (None: none)."""
    args = request.view_args or {}
    if "token" in args:
        query = db.select(Participant.study_id).where(Participant.link_token == args["token"])
    elif "open_token" in args:
        query = db.select(Study.id).where(Study.open_link_token == args["open_token"])
    else:
        value = request.args.get("study", "")
        if not (value.isdigit() and len(value) < 10):
            return None
        query = db.select(Study.id).where(Study.id == int(value))
    return db.session.execute(query).scalar_one_or_none()


def _count_failure(study_id: int | None) -> None:
    row = _current(study_id)
    if row is None:
        # A new window: forget the ended ones (of every address) on the way.
        cutoff = utcnow() - timedelta(seconds=window_s())
        db.session.execute(db.delete(EntryFailures).where(EntryFailures.since <= cutoff))
        db.session.add(EntryFailures(study_id=study_id, address=address(), failures=1, since=utcnow()))
    else:
        db.session.execute(db.update(EntryFailures).where(EntryFailures.id == row.id).values(failures=EntryFailures.failures + 1))
    db.session.commit()


def entry_attempts(view: Callable) -> Callable:
    """Decorate a study-entry view: 429 while this address is locked out of the study the attempt names
    (``entry_study``), and its failures (401, 404) counted there. Successes are never counted."""

    @functools.wraps(view)
    def attempt(**kwargs):
        if not current_app.config["RATELIMIT_ENABLED"]:
            return view(**kwargs)
        study_id = entry_study()
        row = _current(study_id)
        wait = locked_s(row) if row is not None else 0
        if wait:
            response = current_app.make_response(error_response(429, "too_many_requests", _try_again(wait)))
            response.headers["Retry-After"] = str(wait)
            return response
        try:
            response = current_app.make_response(view(**kwargs))
        except Problem as exc:
            if exc.status == 404:
                _count_failure(study_id)
            raise
        if failed(response):
            _count_failure(study_id)
        return response

    return attempt


def entry_locks(study_id: int) -> list[EntryFailures]:
    """The counts a study's page shows: its own and the shared ones (wrong codes without ``?study=``, unknown links)."""
    query = _counting().where(EntryFailures.study_id.is_(None) | (EntryFailures.study_id == study_id))
    return list(db.session.execute(query.order_by(EntryFailures.failures.desc(), EntryFailures.id)).scalars())


def clear_entry_lock(study_id: int, lock_id: int) -> EntryFailures:
    """Forget one count shown on the study's page (404 for any other)."""
    row = db.session.get(EntryFailures, lock_id)
    if row is None or row.study_id not in (None, study_id):
        raise Problem("no such entry lock for this study", status=404)
    db.session.delete(row)
    db.session.commit()
    return row
