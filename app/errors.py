"""One error type, one shape: JSON for API calls, an HTML page for browsers.

Services raise ``Problem`` (egonet raises ``EgonetError``, mapped onto it);
the handlers below answer it, and ``app.cli`` prints it as one line.

API errors are ``{"error": <short name>, "message": <sentence>, "fields":
{<field>: <reason>}}``. A request is an API call when its path starts with
``/api/`` or it prefers JSON. A 500 rolls the session back first; so does
a ``MediaError`` about one of the instance's own files, which is the
server's fault, not the user's. Storage that cannot be reached is a 503
(``StorageUnavailable``), tried again on the next request.
"""

from pathlib import Path

from flask import Flask, current_app, jsonify, make_response, render_template, request
from flask_wtf.csrf import CSRFError
from werkzeug.exceptions import HTTPException, InternalServerError

from app.extensions import db
from egonet.errors import EgonetError
from egonet.io import MediaError


class Problem(Exception):
    """The app's one error: something a user asked for that cannot be done, said in words.

    Services and views raise it (or an area's subclass, such as
    ``StudyProblem``); one handler each turns it into the API's JSON shape,
    the browser's error page and the CLI's one-line failure. egonet's
    ``EgonetError`` is mapped the same way (see ``from_egonet``).

    Args:
        message: The sentence shown to the user.
        field: The input at fault: a form or JSON field, a CLI option or a file.
        status: The HTTP status a view answers with: 400 bad input (default),
            403 not allowed, 404 no such thing, 409 conflict, 410 gone, 413 too large, 415 a body of a type the address does not take.
        fields: ``{field: reason}`` for the JSON's ``fields``; defaults to
            ``{field: message}`` when ``field`` is given.
        **extra: More keys of the JSON body (for example ``reason="time_up"``).
    """

    def __init__(self, message: str, *, field: str | None = None, status: int = 400,
                 fields: dict[str, str] | None = None, **extra):
        super().__init__(message)
        self.message = message
        self.field = field if field is not None else next(iter(fields or {}), None)
        self.status = status
        self.fields = dict(fields) if fields is not None else ({field: message} if field else {})
        self.extra = extra

    @classmethod
    def from_egonet(cls, exc: EgonetError) -> "Problem":
        """egonet's error as the app's: a 400 naming its field (an argument or a file)."""
        return cls(exc.message, field=exc.field, fields={exc.field: exc.reason} if exc.field else {})


class StorageUnavailable(RuntimeError):
    """The site's object store did not answer (connection refused, time-out, 5xx) or refused (no such bucket,
    wrong keys). Raised by ``app.services.storage``; a request gets a 503 that names no bucket, the CLI one line."""


ERROR_NAMES = {400: "bad_request", 404: "not_found", 409: "conflict", 413: "too_large", 415: "unsupported_media_type"}


def wants_json() -> bool:
    if request.path.startswith("/api/"):
        return True
    best = request.accept_mimetypes.best_match(["application/json", "text/html"])
    return best == "application/json" and request.accept_mimetypes[best] > request.accept_mimetypes["text/html"]


def error_response(status: int, name: str, message: str, fields: dict[str, str] | None = None, **extra):
    if wants_json():
        body = {"error": name, "message": message, "fields": fields or {}, **extra}
        return jsonify(body), status
    return render_template("error.html", status=status, name=name, message=message, fields=fields or {}), status


def _is_stored(path: str) -> bool:
    """Whether ``path`` is one of the instance's own files (media, caches, checkpoints)."""
    roots = (current_app.instance_path, current_app.config["STORAGE_URL"], current_app.config["CACHE_ROOT"])
    return any(Path(path).resolve().is_relative_to(Path(root).resolve()) for root in roots)


def register(app: Flask) -> None:
    @app.errorhandler(Problem)
    def handle_problem(exc: Problem):
        return error_response(exc.status, ERROR_NAMES.get(exc.status, "error"), exc.message, exc.fields, **exc.extra)

    @app.errorhandler(EgonetError)
    def handle_egonet_error(exc: EgonetError):
        if isinstance(exc, MediaError) and _is_stored(exc.path):
            return handle_unexpected(exc)  # our own file is broken: the server's fault, and its path stays private
        return handle_problem(Problem.from_egonet(exc))

    @app.errorhandler(CSRFError)
    def handle_csrf(exc: CSRFError):
        # Its own name: a page told "csrf" fetches a fresh token and sends the request again.
        return error_response(400, "csrf", exc.description)

    @app.errorhandler(HTTPException)
    def handle_http(exc: HTTPException):
        if exc.code and exc.code >= 500:
            db.session.rollback()
        name = (exc.name or "error").lower().replace(" ", "_")
        return error_response(exc.code or 500, name, exc.description or exc.name)

    @app.errorhandler(StorageUnavailable)
    def handle_storage_down(exc: StorageUnavailable):
        # The bucket's name and address stay in the log; the next request tries again.
        db.session.rollback()
        app.logger.error("storage unreachable on %s %s: %s", request.method, request.path, exc)
        response = make_response(error_response(503, "storage_unavailable", "File storage is unreachable just now. Try again in a minute."))
        response.headers["Retry-After"] = "30"
        return response

    @app.errorhandler(Exception)
    def handle_unexpected(exc: Exception):
        db.session.rollback()
        app.logger.exception("unhandled error on %s %s", request.method, request.path)
        return error_response(500, "internal_server_error", InternalServerError.description)
