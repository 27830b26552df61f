"""Throttling of guesses (passwords, participant codes, study links) and of open-link admissions.

Flask-Limiter counts failed attempts per key (for log-in: the account and the
client's address) in a fixed window that starts at the first failure. Only
failures count (``deduct_when=failed``), so people who type their password
right are never slowed down, and a success forgets the failures before it
(``forgive``): the limit is on failures in a row. Once ``RATELIMIT_FAILURES``
failures are reached within ``RATELIMIT_WINDOW``, every attempt for that key
is answered 429 with ``Retry-After`` until the window ends, a correct
password included.

A study's open link is public: each admission through it makes a
participant with their trials, so admissions are counted per address too
(``RATELIMIT_ARRIVALS``, default 30 per hour; a participant resuming with
the same platform id is not counted).

Storage: in memory (per server process) by default; Redis when
``RATELIMIT_STORAGE_URI`` is a ``redis://`` URL, or, when it is unset and
the queue's URL (``QUEUE_URL``, from ``EGONET_QUEUE_URL``) is one, that Redis (so several gunicorn processes and
machines share the counts).

The limiter is one object for the process (views are decorated with it at
import). Each ``create_app`` gives it that app's switch, limits and a fresh
store; a few Flask-Limiter settings (``RATELIMIT_KEY_PREFIX``,
``RATELIMIT_STRATEGY``) keep the first app's value, which only matters to a
process that makes several apps (the tests).
"""

import math
import time

from flask import Flask, Response, current_app, request
from flask_limiter import Limiter
from flask_limiter.util import get_remote_address

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
    app.config.setdefault("RATELIMIT_ARRIVALS", "30 per hour")
    app.config["RATELIMIT_STORAGE_URI"] = storage_uri(app)
    app.config.setdefault("RATELIMIT_HEADERS_ENABLED", True)
    limiter.init_app(app)


def failures_limit() -> str:
    """The limit string from the config, e.g. ``20 per 15 minutes``."""
    return f"{current_app.config['RATELIMIT_FAILURES']} per {current_app.config['RATELIMIT_WINDOW']}"


def arrivals_limit() -> str:
    """Admissions through open study links per address (``RATELIMIT_ARRIVALS``)."""
    return current_app.config["RATELIMIT_ARRIVALS"]


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
    wait = max(1, math.ceil(limit.reset_at - time.time())) if limit is not None else None
    if wait is None:
        return "Too many failed attempts. Wait a while, then try again."
    when = f"{wait} seconds" if wait < 90 else f"{round(wait / 60)} minutes"
    return f"Too many failed attempts. Try again in {when}."
