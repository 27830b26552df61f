"""Account commands: list users, change a role, deactivate and activate, set a password.

Every change that takes rights away (a new role, deactivation, a new
password) ends the user's sessions at once. A generated password is printed
once; nothing keeps it.
"""

import sys

import click

from app.cli.group import bp
from app.models import Role, User
from app.services import users


def ask_password(role: Role) -> str | None:
    """The password typed at a terminal (twice), or None to generate one (no terminal, or left empty)."""
    if role is Role.PARTICIPANT or not sys.stdin.isatty():
        return None
    password = click.prompt("Password (empty to generate one)", default="", hide_input=True, show_default=False)
    if password and click.prompt("Repeat", hide_input=True) != password:
        raise click.UsageError("the passwords do not match")
    return password or None


def _user(name: str) -> User:
    user = users.find_user(name)
    if user is None:
        raise click.ClickException(f"no user named {name!r} (see: flask --app app egonet users)")
    return user


def _when(value) -> str:
    return value.strftime("%Y-%m-%d %H:%M") if value is not None else "-"


@bp.cli.command("users")
def users_command():
    """List the staff accounts: role, status, created, last sign-in (UTC)."""
    rows = [("NAME", "ROLE", "STATUS", "CREATED", "LAST SIGN-IN")]
    for user in users.staff_users():
        status = "active" if user.active else "deactivated"
        if user.password_hash is None:
            status += ", no password"
        rows.append((user.username, user.role.value, status, _when(user.created_at), _when(user.last_login_at)))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for row in rows:
        click.echo("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip())


@bp.cli.command("set-role")
@click.argument("name")
@click.argument("role", metavar="ROLE", type=click.Choice([r.value for r in users.STAFF_ROLES]))
def set_role_command(name, role):
    """Give user NAME another staff ROLE (their sessions end)."""
    user = _user(name)
    users.set_role(user, role)
    click.echo(f"{user.username!r} is now {user.role.value}")


@bp.cli.command("deactivate")
@click.argument("name")
def deactivate_command(name):
    """Deactivate user NAME: they are signed out at once and cannot sign in; their work stays theirs."""
    user = _user(name)
    users.set_active(user, False)
    click.echo(f"{user.username!r} is deactivated")


@bp.cli.command("activate")
@click.argument("name")
def activate_command(name):
    """Let a deactivated user NAME sign in again."""
    user = _user(name)
    users.set_active(user, True)
    note = "" if user.password_hash else " (no password yet: use set-password)"
    click.echo(f"{user.username!r} is active{note}")


@bp.cli.command("set-password")
@click.argument("name")
@click.option("--password", help="The new password (prompted when omitted and a terminal is attached; generated otherwise).")
def set_password_command(name, password):
    """Give staff user NAME a new password (their sessions end); a generated one is printed once."""
    user = _user(name)
    generated = users.set_password(user, password or ask_password(user.role))
    click.echo(f"new password for {user.username!r}; their sessions have ended")
    if generated:
        click.echo(f"password: {generated}")
