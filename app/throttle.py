"""Throttling of guesses (passwords, study codes) and of open-link admissions.

The client's address is ``request.remote_addr``: behind a reverse proxy that
is the proxy's, the same for everyone, unless ``TRUSTED_PROXIES`` (the
number of proxies in front) makes the app factory read it from
``X-Forwarded-For`` (Werkzeug's ``ProxyFix``; docs/deployment.md).

Every count is taken *before* the attempt is checked, atomically, so
concurrent requests cannot all pass a check that only one of them should:
a success is then given back.

Passwords (``password_attempts``): a hard lock-out, because it protects a
secret, per account name *and* address, so that a guesser elsewhere cannot
lock the owner out. Flask-Limiter's storage counts attempts in a fixed
window that starts at the first one; a success forgets the count (the limit
is on failures in a row); a request that is neither (a form error) is given
back. Once ``RATELIMIT_FAILURES`` are counted within ``RATELIMIT_WINDOW``,
every attempt for that key is answered 429 with ``Retry-After`` until the
window ends, a correct password included. Storage: in memory (per server
process) by default; Redis when ``RATELIMIT_STORAGE_URI`` is a ``redis://``
URL, or, when it is unset and the queue's URL (``QUEUE_URL``, from
``EGONET_QUEUE_URL``) is one, that Redis (so several gunicorn processes and
machines share the counts).

Study entry (``entry_attempts``, ``open_admission``): slowed down, never
locked, because a class behind one address (a lab, a university's NAT)
shares it with whoever is guessing. Counted in the database
(``EntryCount``, one row per scope, address and window, so every server
process shares them and staff see and clear them on the study's page):

- ``codes``: wrong codes and unknown single-use links per address, whatever
  study the URL names (codes are looked up across all studies).
  ``RATELIMIT_ENTRY_FAILURES`` (200) per window are free; after that each
  one makes the address wait 1, 2, 4, ... up to ``RATELIMIT_ENTRY_MAX_WAIT``
  seconds before its next attempt is checked (429 with ``Retry-After``
  meanwhile). ``most_guesses`` is the arithmetic of docs/security.md.
- ``open-<study>``: admissions of newcomers through a study's open link per
  address, ``RATELIMIT_OPEN_ADMISSIONS`` (150) free per window, then the
  same waits. Wrong codes never slow the open link down (it takes no secret).

The limiter is one object for the process (views are decorated at import).
Each ``create_app`` gives it that app's switch and a fresh store; a few
Flask-Limiter settings (``RATELIMIT_KEY_PREFIX``, ``RATELIMIT_STRATEGY``)
keep the first app's value, which only matters to a process that makes
several apps (the tests).
"""

import functools
import math
import time
from collections.abc import Callable
from datetime import timedelta

from flask import Flask, Response, current_app, request
from flask_limiter import Limiter
from limits import parse
from sqlalchemy import case, literal
from sqlalchemy.dialects import postgresql, sqlite

from app.errors import Problem, error_response
from app.extensions import db
from app.models.base import UTCDateTime, utcnow
from app.models.studies import EntryCount

limiter = Limiter(key_func=lambda: request.remote_addr, default_limits=[], headers_enabled=True)
CODES = "codes"


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
    app.config.setdefault("RATELIMIT_ENTRY_MAX_WAIT", 30)
    app.config.setdefault("RATELIMIT_OPEN_ADMISSIONS", 150)
    app.config["RATELIMIT_STORAGE_URI"] = storage_uri(app)
    app.config.setdefault("RATELIMIT_HEADERS_ENABLED", True)
    limiter.init_app(app)


def address() -> str:
    return request.remote_addr or "unknown"


def failed(response: Response) -> bool:
    """A refused attempt: a wrong password or code (401), or an unknown link (404)."""
    return response.status_code in (401, 404)


def _try_again(wait: int) -> str:
    when = f"{wait} seconds" if wait < 90 else f"{round(wait / 60)} minutes"
    return f"Too many failed attempts. Try again in {when}."


def too_many(wait: int) -> Response:
    response = current_app.make_response(error_response(429, "too_many_requests", _try_again(wait)))
    response.headers["Retry-After"] = str(wait)
    return response


def password_attempts(key: Callable[[], str]) -> Callable:
    """Decorate a view that checks a password on POST: counted per ``key()`` (account and address), see above."""

    def decorate(view: Callable) -> Callable:
        @functools.wraps(view)
        def attempt(**kwargs):
            if request.method != "POST" or not current_app.config["RATELIMIT_ENABLED"]:
                return view(**kwargs)
            item = parse(f"{current_app.config['RATELIMIT_FAILURES']} per {current_app.config['RATELIMIT_WINDOW']}")
            ids = ("password", key())
            if not limiter.limiter.hit(item, *ids):
                limiter.limiter.hit(item, *ids, cost=-1)  # refused unchecked: the count stays that of checked ones
                return too_many(max(1, math.ceil(limiter.limiter.get_window_stats(item, *ids).reset_time - time.time())))
            response = current_app.make_response(view(**kwargs))
            if response.status_code < 400:
                limiter.limiter.clear(item, *ids)  # a success ends a run of failures
            elif not failed(response):
                limiter.limiter.hit(item, *ids, cost=-1)  # not a guess: given back
            return response

        return attempt

    return decorate


def window_s() -> int:
    """``RATELIMIT_WINDOW`` in seconds."""
    return parse(f"1 per {current_app.config['RATELIMIT_WINDOW']}").get_expiry()


def waits(free: int, max_wait: int, count: int) -> int:
    """Seconds the address waits after its ``count``-th attempt in a window (0 within the ``free`` ones)."""
    beyond = count - free
    return 0 if beyond <= 0 else min(2 ** min(beyond - 1, 32), max_wait)


def most_guesses(free: int, max_wait: int, window: int) -> int:
    """The most attempts one address can have checked in one window: the free ones at once, then one per wait."""
    count, elapsed = free + 1, 0
    while elapsed + waits(free, max_wait, count) < window:
        elapsed += waits(free, max_wait, count)
        count += 1
    return count


def _insert():
    return (postgresql.insert if db.engine.dialect.name == "postgresql" else sqlite.insert)(EntryCount)


def _take(scope: str, study_id: int | None, free: int) -> int:
    """Count one attempt of this address in ``scope`` before it is checked: 0, or the seconds it must wait first."""
    now, span = utcnow(), window_s()
    window = int(now.timestamp()) // span
    where = (EntryCount.scope == scope, EntryCount.address == address(), EntryCount.window == window)
    made = db.session.execute(
        _insert()
        .values(scope=scope, study_id=study_id, address=address(), window=window, count=0, since=now)
        .on_conflict_do_nothing(index_elements=["scope", "address", "window"])
    )
    if made.rowcount:  # a new window: forget the ended ones (of every address) on the way
        db.session.execute(db.delete(EntryCount).where(EntryCount.window < window - 1))
    max_wait = current_app.config["RATELIMIT_ENTRY_MAX_WAIT"]
    # The wait this attempt sets, by the count it makes: one statement, so concurrent attempts queue on the row.
    def at(count: int):
        return literal(now + timedelta(seconds=waits(free, max_wait, count)), UTCDateTime())

    wait_until = case(
        (EntryCount.count + 1 <= free, EntryCount.wait_until),
        *((EntryCount.count + 1 == count, at(count)) for count in range(free + 1, free + max_wait.bit_length() + 1)),
        else_=at(free + max_wait.bit_length() + 1),
    )
    counted = db.session.execute(
        db.update(EntryCount)
        .where(*where, EntryCount.wait_until.is_(None) | (EntryCount.wait_until <= now))
        .values(count=EntryCount.count + 1, wait_until=wait_until)
        .returning(EntryCount.id)
    ).first()
    until = None if counted else db.session.execute(db.select(EntryCount.wait_until).where(*where)).scalar_one()
    db.session.commit()
    return 0 if until is None else max(1, math.ceil((until - now).total_seconds()))


def _give_back(scope: str) -> None:
    """Uncount this address's last attempt in ``scope`` (it succeeded, or was no attempt)."""
    window = int(utcnow().timestamp()) // window_s()
    db.session.rollback()
    db.session.execute(
        db.update(EntryCount)
        .where(EntryCount.scope == scope, EntryCount.address == address(), EntryCount.window == window, EntryCount.count > 0)
        .values(count=EntryCount.count - 1)
    )
    db.session.commit()


def entry_attempts(view: Callable) -> Callable:
    """Decorate a view that takes a code or a single-use link: each attempt is counted in ``codes`` before it
    is checked, 429 while the address waits, and every answer but a wrong code (401) or unknown link (404) is given back."""

    @functools.wraps(view)
    def attempt(**kwargs):
        if request.method != "POST" and "token" not in kwargs or not current_app.config["RATELIMIT_ENABLED"]:
            return view(**kwargs)
        wait = _take(CODES, None, current_app.config["RATELIMIT_ENTRY_FAILURES"])
        if wait:
            return too_many(wait)
        try:
            response = current_app.make_response(view(**kwargs))
        except Problem as exc:
            if exc.status != 404:
                _give_back(CODES)
            raise
        if not failed(response):
            _give_back(CODES)
        return response

    return attempt


def open_scope(study_id: int) -> str:
    return f"open-{study_id}"


def open_admission(study_id: int) -> int:
    """Count one newcomer's admission through the study's open link from this address: 0, or seconds to wait."""
    if not current_app.config["RATELIMIT_ENABLED"]:
        return 0
    return _take(open_scope(study_id), study_id, current_app.config["RATELIMIT_OPEN_ADMISSIONS"])


def not_admitted(study_id: int) -> None:
    """Give back an admission counted by ``open_admission`` that did not happen (full, paused, a bad id)."""
    if current_app.config["RATELIMIT_ENABLED"]:
        _give_back(open_scope(study_id))


def locked_s(row: EntryCount) -> int:
    """Seconds until ``row``'s address may try again (0: now)."""
    if row.wait_until is None:
        return 0
    return max(0, math.ceil((row.wait_until - utcnow()).total_seconds()))


def entry_locks(study_id: int) -> list[EntryCount]:
    """The counts a study's page shows, of the current window: every address's codes, and its own open link's admissions."""
    window = int(utcnow().timestamp()) // window_s()
    query = db.select(EntryCount).where(EntryCount.window == window, EntryCount.count > 0)
    query = query.where((EntryCount.scope == CODES) | (EntryCount.scope == open_scope(study_id)))
    return list(db.session.execute(query.order_by(EntryCount.count.desc(), EntryCount.id)).scalars())


def clear_entry_lock(study_id: int, lock_id: int) -> EntryCount:
    """Forget one count shown on the study's page (404 for any other)."""
    row = db.session.get(EntryCount, lock_id)
    if row is None or row.scope not in (CODES, open_scope(study_id)):
        raise Problem("no such entry count for this study", status=404)
    db.session.delete(row)
    db.session.commit()
    return row
