"""User accounts."""

import secrets

from werkzeug.security import check_password_hash, generate_password_hash

from app.extensions import db
from app.models import Role, User


class UserProblem(ValueError):
    """A user that cannot be created, with the reason."""


def find_user(username: str) -> User | None:
    return db.session.execute(db.select(User).filter_by(username=username.strip())).scalar_one_or_none()


def create_user(username: str, role: Role | str, password: str | None = None) -> tuple[User, str | None]:
    """Create a user; return it and the generated password (None when one was given).

    Passwords are hashed with Werkzeug's scrypt. Participants have no
    password: they enter through their study code.
    """
    username = username.strip()
    if not username or len(username) > 80:
        raise UserProblem("NAME must be 1-80 characters")
    try:
        role = Role(role)
    except ValueError:
        raise UserProblem(f"unknown role {role!r}; use one of {', '.join(r.value for r in Role)}") from None
    if find_user(username) is not None:
        raise UserProblem(f"a user named {username!r} already exists")
    generated = None
    if role is Role.PARTICIPANT:
        password_hash = None
    else:
        if not password:
            password = generated = secrets.token_urlsafe(12)
        if len(password) < 8:
            raise UserProblem("the password must have at least 8 characters")
        password_hash = generate_password_hash(password)
    user = User(username=username, role=role, password_hash=password_hash)
    db.session.add(user)
    db.session.commit()
    return user, generated


def authenticate(username: str, password: str) -> User | None:
    """The active staff user with this name and password, or None.

    Participants have no password and never sign in here. The hash is checked
    even for unknown names, so timing does not reveal which names exist.
    """
    user = find_user(username)
    stored = user.password_hash if user is not None and user.password_hash else _DUMMY_HASH
    ok = check_password_hash(stored, password)
    if user is None or not ok or not user.active or user.role is Role.PARTICIPANT:
        return None
    return user


_DUMMY_HASH = generate_password_hash("not-a-real-password")
