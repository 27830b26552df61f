"""One error shape: JSON for API calls, an HTML page for browsers.

API errors are ``{"error": <short name>, "message": <sentence>, "fields":
{<field>: <reason>}}``. A request is an API call when its path starts with
``/api/`` or it prefers JSON. A 500 rolls the session back first.
"""

from flask import Flask, jsonify, render_template, request
from flask_wtf.csrf import CSRFError
from werkzeug.exceptions import HTTPException, InternalServerError

from app.extensions import db


class Problem(ValueError):
    """A request a service cannot carry out; ``field`` names the bad input when there is one.

    The CLI prints it as a one-line error; views turn it into a 400 naming the field.
    """

    def __init__(self, message: str, *, field: str | None = None):
        super().__init__(message)
        self.field = field


class ApiError(Exception):
    """Raised by views and services to answer a 4xx with a message and fields."""

    def __init__(self, status: int, message: str, *, fields: dict[str, str] | None = None, **extra):
        super().__init__(message)
        self.status = status
        self.message = message
        self.fields = fields or {}
        self.extra = extra


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


def register(app: Flask) -> None:
    @app.errorhandler(ApiError)
    def handle_api_error(exc: ApiError):
        name = {400: "bad_request", 404: "not_found", 409: "conflict", 413: "too_large"}.get(exc.status, "error")
        return error_response(exc.status, name, exc.message, exc.fields, **exc.extra)

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

    @app.errorhandler(Exception)
    def handle_unexpected(exc: Exception):
        db.session.rollback()
        app.logger.exception("unhandled error on %s %s", request.method, request.path)
        return error_response(500, "internal_server_error", InternalServerError.description)
