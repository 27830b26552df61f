"""Throttling of guesses: passwords, participant codes, single-use links.

Flask-Limiter counts failed attempts per key (for log-in: the account and the
client's address) in a fixed window. Only failures count (``deduct_when``),
so people who type their password right are never slowed down; once
``RATELIMIT_FAILURES`` failures are reached within the window, every attempt
for that key is answered 429 with ``Retry-After`` until the window ends.

Storage: in memory (per server process) by default; Redis when
``RATELIMIT_STORAGE_URI`` is a ``redis://`` URL, or, when it is unset and
``EGONET_QUEUE_URL`` is one, that Redis (so several gunicorn processes and
machines share the counts).
"""

import os

from flask import Flask, Response, request
from flask_limiter import Limiter
from flask_limiter.util import get_remote_address

limiter = Limiter(key_func=get_remote_address, default_limits=[], headers_enabled=True)


def storage_uri(app: Flask) -> str:
    configured = app.config.get("RATELIMIT_STORAGE_URI")
    if configured:
        return configured
    queue = os.environ.get("EGONET_QUEUE_URL", "")
    return queue if queue.startswith(("redis://", "rediss://")) else "memory://"


def init_app(app: Flask) -> None:
    app.config.setdefault("RATELIMIT_FAILURES", 20)
    app.config.setdefault("RATELIMIT_WINDOW", "15 minutes")
    app.config["RATELIMIT_STORAGE_URI"] = storage_uri(app)
    app.config.setdefault("RATELIMIT_HEADERS_ENABLED", True)
    limiter.init_app(app)


def failures_limit() -> str:
    """The limit string from the config, e.g. ``20 per 15 minutes``."""
    from flask import current_app

    return f"{current_app.config['RATELIMIT_FAILURES']} per {current_app.config['RATELIMIT_WINDOW']}"


def failed(response: Response) -> bool:
    """A refused attempt: a wrong password or code (401), or an unknown link (404)."""
    return response.status_code in (401, 404)


def address() -> str:
    return get_remote_address() or request.remote_addr or "unknown"
