"""Accounts: each person's own password, and the admin's list of staff users.

Admins create staff accounts, change roles, deactivate and reactivate them
and reset passwords; users are never deleted, so their annotations stay
attributed. A generated password is shown once, on the page that answers the
POST, and never stored anywhere readable. Each change that takes rights
away ends the user's sessions at once (app/services/users.py).
"""

from flask import Blueprint, flash, redirect, render_template, url_for
from flask_login import current_user
from wtforms import PasswordField, SelectChoice, SelectField, StringField
from wtforms.validators import DataRequired, EqualTo, Length

from app.blueprints.auth import sign_in
from app.errors import Problem
from app.extensions import db
from app.forms import Form
from app.models import Role, User
from app.security import roles
from app.services import users
from app.throttle import address, password_attempts

bp = Blueprint("users", __name__)

ROLE_CHOICES = [SelectChoice(role.value, role.value) for role in users.STAFF_ROLES]


class PasswordForm(Form):
    current_password = PasswordField("Current password", validators=[DataRequired(), Length(max=users.MAX_PASSWORD_LENGTH)])
    new_password = PasswordField("New password", validators=[DataRequired(), Length(max=users.MAX_PASSWORD_LENGTH)])
    repeat = PasswordField(
        "Repeat the new password", validators=[DataRequired(), EqualTo("new_password", message="The two new passwords differ.")]
    )


class NewUserForm(Form):
    username = StringField("Username", validators=[DataRequired(), Length(max=80)])
    role = SelectField("Role", choices=ROLE_CHOICES, default=Role.ANNOTATOR.value)


class RoleForm(Form):
    role = SelectField("Role", choices=ROLE_CHOICES)


class ConfirmForm(Form):
    """A POST with nothing but its CSRF token (deactivate, activate, reset)."""


def _staff_user(user_id: int) -> User:
    """A staff account by id; participants are managed in their study (404 here)."""
    user = db.session.get(User, user_id)
    if user is None or user.role is Role.PARTICIPANT:
        raise Problem("no such staff account", status=404)
    return user


def _account_key() -> str:
    """Wrong current passwords count per account and address, like wrong log-in passwords."""
    return f"{address()}/{current_user.id}"


def _index(new_user: NewUserForm, status: int = 200):
    return render_template("users/index.html", users=users.staff_users(), new_user=new_user, roles=users.STAFF_ROLES), status


def _new_password_page(user: User, password: str, *, created: bool):
    response = render_template("users/password.html", user=user, password=password, created=created)
    return response, 200, {"Cache-Control": "no-store"}


@bp.route("/account", methods=["GET", "POST"])
@password_attempts(_account_key)
def account():
    """Change one's own password: the current one is required, and other sessions end."""
    form = PasswordForm()
    status = 200
    if form.validate_on_submit():
        user = current_user._get_current_object()
        if not users.check_password(user, form.current_password.data):
            form.current_password.errors.append("This is not your current password.")
            status = 401
        else:
            try:
                users.set_password(user, form.new_password.data)
            except users.UserProblem as exc:
                form.new_password.errors.append(str(exc))
                status = 400
            else:
                sign_in(user)  # this session goes on with the new token; every other one has ended
                flash("Password changed. Other sessions have been signed out.")
                return redirect(url_for("users.account"))
    elif form.errors:
        status = 400
    return render_template("users/account.html", form=form, min_length=users.MIN_PASSWORD_LENGTH), status


@bp.get("/users/")
@roles(Role.ADMIN)
def index():
    return _index(NewUserForm(formdata=None))


@bp.post("/users/")
@roles(Role.ADMIN)
def create():
    form = NewUserForm()
    if form.validate_on_submit():
        try:
            user, password = users.create_user(form.username.data, form.role.data)
        except users.UserProblem as exc:
            form.username.errors.append(str(exc))
        else:
            return _new_password_page(user, password, created=True)
    return _index(form, 400)


@bp.post("/users/<int:user_id>/role")
@roles(Role.ADMIN)
def set_role(user_id: int):
    user = _staff_user(user_id)
    form = RoleForm()
    if not form.validate_on_submit():
        raise Problem("choose one of the staff roles", fields={"role": "; ".join(form.role.errors) or "missing"})
    try:
        changed = users.set_role(user, form.role.data)
    except users.UserProblem as exc:
        return _refused(str(exc))
    flash(f"{user.username} is now {user.role.value}; their sessions have ended." if changed else f"{user.username} is {user.role.value} already.")
    return redirect(url_for("users.index"))


@bp.post("/users/<int:user_id>/deactivate")
@roles(Role.ADMIN)
def deactivate(user_id: int):
    return _set_active(_staff_user(user_id), False)


@bp.post("/users/<int:user_id>/activate")
@roles(Role.ADMIN)
def activate(user_id: int):
    return _set_active(_staff_user(user_id), True)


def _set_active(user: User, active: bool):
    if not ConfirmForm().validate_on_submit():
        raise Problem("the form is not valid; reload the page and try again")
    try:
        users.set_active(user, active)
    except users.UserProblem as exc:
        return _refused(str(exc))
    if active and user.password_hash is None:
        flash(f"{user.username} is active; reset their password so they can sign in.")
    elif active:
        flash(f"{user.username} can sign in again.")
    else:
        flash(f"{user.username} is deactivated and signed out everywhere.")
    return redirect(url_for("users.index"))


@bp.post("/users/<int:user_id>/password")
@roles(Role.ADMIN)
def reset_password(user_id: int):
    user = _staff_user(user_id)
    if not ConfirmForm().validate_on_submit():
        raise Problem("the form is not valid; reload the page and try again")
    password = users.set_password(user)
    return _new_password_page(user, password, created=False)


def _refused(message: str):
    """A change the rules refuse (the last admin): the list again, with the reason."""
    flash(message, "error")
    return _index(NewUserForm(formdata=None), 400)
