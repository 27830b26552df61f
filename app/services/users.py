"""User accounts: creating them, their passwords, roles and sessions.

Staff sign in with a password; participants have none (they enter with their
study code). Every change that should end a user's sessions elsewhere (a new
password, a new role, deactivation, signing out) replaces the user's session
token, which every session and remember-me cookie carries.
"""

import secrets

from werkzeug.security import check_password_hash, generate_password_hash
from zxcvbn import zxcvbn

from app.errors import Problem
from app.extensions import db
from app.models import Role, User, utcnow

MIN_PASSWORD_LENGTH = 10
MAX_PASSWORD_LENGTH = 200
# zxcvbn scores 0-4; 2 ("somewhat guessable") takes more than a million
# guesses, which an online attack slowed by the log-in throttle never makes.
MIN_PASSWORD_SCORE = 2
# zxcvbn refuses longer input; a password this long is not short, so the
# score of its beginning is enough to catch repeats and common phrases.
ZXCVBN_MAX_LENGTH = 72
STAFF_ROLES = (Role.ADMIN, Role.ANNOTATOR, Role.REVIEWER)


class UserProblem(Problem):
    """A change to a user that cannot be made, with the reason (and the field)."""


def find_user(username: str) -> User | None:
    return db.session.execute(db.select(User).filter_by(username=username.strip())).scalar_one_or_none()


def staff_users() -> list[User]:
    """Every account that signs in with a password, by name (participants belong to their study)."""
    return list(db.session.execute(db.select(User).where(User.role != Role.PARTICIPANT).order_by(User.username)).scalars())


def password_problem(password: str, username: str) -> str | None:
    """Why ``password`` is refused for ``username`` (one sentence), or None when it is fine."""
    if len(password) < MIN_PASSWORD_LENGTH:
        return f"the password must have at least {MIN_PASSWORD_LENGTH} characters"
    if len(password) > MAX_PASSWORD_LENGTH:
        return f"the password must have at most {MAX_PASSWORD_LENGTH} characters"
    verdict = zxcvbn(password[:ZXCVBN_MAX_LENGTH], user_inputs=[username, "egonet", "studio"])
    if verdict["score"] < MIN_PASSWORD_SCORE:
        feedback = verdict["feedback"]
        advice = " ".join([feedback["warning"], *feedback["suggestions"]]).strip() or "Add another word or two."
        return f"the password is too easy to guess: {advice}"
    return None


def generate_password(username: str) -> str:
    """A random password (96 bits) that passes the policy for this user."""
    while True:
        password = secrets.token_urlsafe(12)
        if password_problem(password, username) is None:
            return password


def _role(role: Role | str) -> Role:
    try:
        return Role(role)
    except ValueError:
        raise UserProblem(f"unknown role {role!r}; use one of {', '.join(r.value for r in Role)}", field="role") from None


def create_user(username: str, role: Role | str, password: str | None = None) -> tuple[User, str | None]:
    """Create a user; return it and the generated password (None when one was given).

    Passwords are hashed with Werkzeug's scrypt and must pass the policy
    (``password_problem``). Participants have no password: they enter
    through their study code.
    """
    username = username.strip()
    if not username or len(username) > 80:
        raise UserProblem("NAME must be 1-80 characters", field="username")
    role = _role(role)
    if find_user(username) is not None:
        raise UserProblem(f"a user named {username!r} already exists", field="username")
    generated = None
    if role is Role.PARTICIPANT:
        password_hash = None
    else:
        if not password:
            password = generated = generate_password(username)
        if problem := password_problem(password, username):
            raise UserProblem(problem, field="password")
        password_hash = generate_password_hash(password)
    user = User(username=username, role=role, password_hash=password_hash)
    db.session.add(user)
    db.session.commit()
    return user, generated


def set_password(user: User, password: str | None = None) -> str | None:
    """Give a staff user a new password (generated when None, and returned) and end their sessions."""
    if user.role is Role.PARTICIPANT:
        raise UserProblem(f"{user.username!r} is a participant: participants have no password", field="password")
    generated = None
    if password is None:
        password = generated = generate_password(user.username)
    elif problem := password_problem(password, user.username):
        raise UserProblem(problem, field="password")
    user.password_hash = generate_password_hash(password)
    user.end_sessions()
    db.session.commit()
    return generated


def _keep_an_admin(user: User) -> None:
    """Refuse to take away the last active admin: nobody could manage accounts any more.

    The active admins are locked (on PostgreSQL) until the commit, so two
    admins demoting each other at once cannot both succeed.
    """
    if user.role is not Role.ADMIN or not user.active:
        return
    admins = db.session.execute(db.select(User.id).where(User.role == Role.ADMIN, User.active).with_for_update()).scalars().all()
    if admins == [user.id]:
        raise UserProblem(f"{user.username!r} is the last active admin; make another user admin first", field="role")


def set_role(user: User, role: Role | str) -> bool:
    """Change a staff user's role; their sessions end, so the new role applies at once.

    Returns whether the role changed (the same role again changes nothing).
    """
    role = _role(role)
    if user.role is Role.PARTICIPANT or role is Role.PARTICIPANT:
        raise UserProblem(
            "participants are made and managed in their study; roles change between admin, annotator and reviewer", field="role"
        )
    if role is user.role:
        return False
    _keep_an_admin(user)
    user.role = role
    user.end_sessions()
    db.session.commit()
    return True


def set_active(user: User, active: bool) -> None:
    """Deactivate (ending every session at once) or reactivate a user.

    Users are never deleted: their annotations, reviews and studies stay
    attributed to them.
    """
    if user.active == active:
        return
    if not active:
        _keep_an_admin(user)
        user.end_sessions()
    user.active = active
    db.session.commit()


def authenticate(username: str, password: str) -> User | None:
    """The active staff user with this name and password, or None.

    Participants and accounts without a password (imported mask authors)
    never sign in here. The hash is checked even for unknown names, so timing
    does not reveal which names exist.
    """
    user = find_user(username)
    has_password = user is not None and user.password_hash is not None
    ok = check_password_hash(user.password_hash if has_password else _DUMMY_HASH, password)
    if not has_password or not ok or not user.active or user.role is Role.PARTICIPANT:
        return None
    return user


def check_password(user: User, password: str) -> bool:
    """Whether ``password`` is this user's password (False for accounts without one)."""
    return user.password_hash is not None and check_password_hash(user.password_hash, password)


def record_sign_in(user: User) -> None:
    user.last_login_at = utcnow()
    db.session.commit()


def sign_out(user: User) -> None:
    """End every session of this user: a session cookie copied before log-out is refused afterwards."""
    user.end_sessions()
    db.session.commit()


def user_for_session(user_id: str) -> User | None:
    """The user a session or remember-me cookie names (``"<id>:<token>"``), when the token is current."""
    ident, _, token = user_id.partition(":")
    if not (ident.isascii() and ident.isdigit() and len(ident) <= 18 and token):
        return None
    user = db.session.get(User, int(ident))
    if user is None or not secrets.compare_digest(user.session_token.encode(), token.encode()):
        return None
    return user


_DUMMY_HASH = generate_password_hash("not-a-real-password")
