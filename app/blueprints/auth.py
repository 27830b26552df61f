"""Signing in and out (staff only: participants enter through their study code).

Wrong passwords are throttled per account name and client address
(app/throttle.py): after ``RATELIMIT_FAILURES`` failures in a row the form
answers 429 until the window ends, for that account from that address only
(its owner elsewhere still signs in). Signing out ends the session on the
server too: the user's session token is replaced, so a copy of the cookie
(or of the remember-me cookie) stops working.
"""

from urllib.parse import urlsplit

from flask import Blueprint, current_app, flash, g, redirect, render_template, request, session, url_for
from flask_login import current_user, login_required, login_user, logout_user
from wtforms import BooleanField, PasswordField, StringField
from wtforms.validators import DataRequired, Length

from app.forms import Form
from app.models import User
from app.security import public
from app.services.users import authenticate, record_sign_in, sign_out
from app.throttle import address, password_attempts

bp = Blueprint("auth", __name__)


class LoginForm(Form):
    username = StringField("Username", validators=[DataRequired(), Length(max=80)])
    password = PasswordField("Password", validators=[DataRequired(), Length(max=200)])
    remember = BooleanField("Keep me signed in")


def safe_next(target: str | None) -> str:
    """Only same-site relative paths: never redirect to another host."""
    if target and target.startswith("/") and not target.startswith("//") and not urlsplit(target).netloc:
        return target
    return url_for("frames.index")


def login_key() -> str:
    """Failures count per account name and client address: one guesser cannot lock others out."""
    return f"{address()}/{(request.form.get('username') or '').strip()[:80]}"


def sign_in(user: User, *, remember: bool = False) -> bool:
    """Start a fresh session for ``user`` (False when the account is inactive).

    Whatever the session held before is dropped, its CSRF token included
    (Flask-WTF makes a new one on the next page), so a session planted in
    the browser before log-in (fixation) knows nothing of this one.
    """
    session.clear()
    g.pop(current_app.config.get("WTF_CSRF_FIELD_NAME", "csrf_token"), None)  # Flask-WTF's per-request copy
    return login_user(user, remember=remember)


@bp.route("/login", methods=["GET", "POST"])
@public
@password_attempts(login_key)
def login():
    form = LoginForm()
    if form.validate_on_submit():
        user = authenticate(form.username.data, form.password.data)
        if user is not None:
            sign_in(user, remember=form.remember.data)
            record_sign_in(user)
            return redirect(safe_next(request.args.get("next")))
        flash("Unknown user or wrong password.", "error")
        return render_template("auth/login.html", form=form), 401
    return render_template("auth/login.html", form=form), 400 if form.errors else 200


@bp.post("/logout")
@public
@login_required
def logout():
    sign_out(current_user._get_current_object())
    session.clear()
    logout_user()
    return redirect(url_for("auth.login"))
