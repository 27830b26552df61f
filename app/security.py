"""Who may reach what: default-deny access rules checked before every request.

Every view is for signed-in staff (admin, annotator, reviewer) unless it
says otherwise with one of these decorators:

    @public             anyone (log-in page, static files, participant entry)
    @roles(Role.ADMIN)  only these roles

A route added without a decorator is therefore staff-only, never open. An
API call that fails the check gets 401/403 JSON; a page redirects to the
log-in page (401) or shows a 403 page.

Every response also carries the headers of ``secure_headers``: a Content
Security Policy that runs no inline script or style (pages load their code
from ``static/js`` and their styles from ``static/css``), no framing, no
MIME sniffing, and HSTS in production. Anything served behind the log-in
that may be cached (frames, masks, previews) is cached by the browser only
(``private``), never by a shared cache.
"""

from collections.abc import Callable

from flask import Flask, Response, current_app, redirect, request, url_for
from flask_login import current_user

from app.errors import error_response, wants_json
from app.limits import MIN_SECRET_KEY_LENGTH
from app.models import Role
from app.validation import check_request

STAFF = frozenset({Role.ADMIN, Role.ANNOTATOR, Role.REVIEWER})

CONTENT_SECURITY_POLICY = "; ".join(
    [
        "default-src 'self'",
        "script-src 'self'",
        "style-src 'self'",
        "img-src 'self' data: blob:",  # and images a page makes itself (from a canvas or a fetched blob)
        "connect-src 'self'",
        "object-src 'none'",
        "base-uri 'self'",
        "form-action 'self'",
        "frame-ancestors 'none'",
    ]
)
HSTS = "max-age=31536000"


def public(view: Callable) -> Callable:
    view.access = None
    return view


def roles(*allowed: Role) -> Callable[[Callable], Callable]:
    def decorate(view: Callable) -> Callable:
        view.access = frozenset(allowed)
        return view

    return decorate


def access_of(view: Callable) -> frozenset[Role] | None:
    """The roles a view admits (None: public); staff by default."""
    return getattr(view, "access", STAFF)


def current_role() -> Role | None:
    return current_user.role if current_user.is_authenticated else None


def check_access():
    """before_request hook: refuse requests the current user may not make."""
    if request.endpoint is None:  # 404 and 405 are answered by Flask itself
        return None
    if request.endpoint == "static":
        return None
    view = current_app.view_functions[request.endpoint]
    allowed = access_of(view)
    if allowed is None:
        return None
    role = current_role()
    if role is None:
        if wants_json():
            return error_response(401, "unauthorized", "sign in first")
        if Role.PARTICIPANT in allowed and Role.ADMIN not in allowed:
            return redirect(url_for("study.entry"))  # participants enter with their code
        return redirect(url_for("auth.login", next=request.full_path.rstrip("?")))
    if role not in allowed:
        return error_response(403, "forbidden", f"the {role.value} role cannot use this")
    return None


def secure_headers(response: Response) -> Response:
    """after_request hook: the security headers every response carries.

    A response that may be cached (it has a Cache-Control other than
    ``no-store``) is marked ``private`` unless it is a static file: what is
    served behind the log-in stays in the signed-in browser's own cache.
    """
    headers = response.headers
    headers.setdefault("Content-Security-Policy", CONTENT_SECURITY_POLICY)
    headers.setdefault("X-Content-Type-Options", "nosniff")
    if "frame-ancestors 'none'" in headers["Content-Security-Policy"]:
        headers.setdefault("X-Frame-Options", "DENY")  # pages that may be framed say by whom in their policy
    headers.setdefault("Referrer-Policy", "same-origin")
    if current_app.config.get("PRODUCTION"):
        headers.setdefault("Strict-Transport-Security", HSTS)
    if request.endpoint != "static" and "Cache-Control" in headers and not response.cache_control.no_store:
        response.cache_control.public = False
        response.cache_control.private = True
    return response


def register(app: Flask) -> None:
    app.before_request(check_access)
    app.before_request(check_request)  # after the access check: nothing is read for whom may not ask
    app.after_request(secure_headers)


def require_production_safety(app: Flask) -> None:
    """In production: refuse a short secret key, send cookies over HTTPS only."""
    if app.config.get("PRODUCTION"):
        if len(app.config.get("SECRET_KEY") or "") < MIN_SECRET_KEY_LENGTH:
            raise RuntimeError(
                f"PRODUCTION is set but SECRET_KEY is shorter than {MIN_SECRET_KEY_LENGTH} characters: "
                "set FLASK_SECRET_KEY to a long random value, or leave it unset to use instance/secret_key"
            )
        app.config["SESSION_COOKIE_SECURE"] = True
        app.config["REMEMBER_COOKIE_SECURE"] = True
