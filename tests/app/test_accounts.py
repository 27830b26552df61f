"""Accounts people can manage: the password policy, one's own password, the
admin's Users page and the account commands; every change that takes rights
away ends the user's sessions at once."""

import re

import pytest
import sqlalchemy as sa
from flask_migrate import downgrade, upgrade
from werkzeug.security import check_password_hash

from app.extensions import db
from app.models import Role, User
from app.services import users
from tests.app.conftest import PASSWORD

NEW_PASSWORD = "saffron kettle orbit"


def signed_in(app, username: str, password: str = PASSWORD):
    """Another browser, signed in as ``username``."""
    other = app.test_client()
    assert other.login(username, password).status_code == 302
    return other


def user_named(app, username: str) -> User:
    with app.app_context():
        user = users.find_user(username)
        db.session.expunge(user)
        return user


def shown_password(response) -> str:
    return re.search(rb'id="new-password">([^<]+)<', response.data).group(1).decode()


# The policy


@pytest.mark.parametrize(
    "password, username, reason",
    [
        ("short1", "ana", "at least 10 characters"),
        ("x" * 201, "ana", "at most 200 characters"),
        ("qwertyuiop", "ana", "top-100 common password"),
        ("Password123!", "ana", "similar to a commonly used password"),
        ("aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa", "ana", 'Repeats like "aaa"'),
        ("zanzibar-mia", "zanzibar-mia", "too easy to guess"),  # the user's own name
    ],
)
def test_weak_passwords_are_refused_with_the_reason(ctx, password, username, reason):
    problem = users.password_problem(password, username)
    assert problem is not None and reason in problem
    with pytest.raises(users.UserProblem, match=re.escape(reason)) as caught:
        users.create_user(username, Role.ANNOTATOR, password)
    assert caught.value.field == "password"


def test_good_and_generated_passwords_pass(ctx):
    assert users.password_problem("zanzibar-mia", "bob") is None  # weak only as one's own name
    assert users.password_problem(PASSWORD, "admin") is None
    assert users.password_problem(NEW_PASSWORD, "ana") is None
    for _ in range(20):
        assert users.password_problem(users.generate_password("ana"), "ana") is None
    _, generated = users.create_user("ana", Role.ANNOTATOR)
    assert users.password_problem(generated, "ana") is None


# One's own password


def test_changing_ones_password_needs_the_current_one_and_ends_other_sessions(app, client, make_user):
    make_user("annotator", "ana")
    other = signed_in(app, "ana")
    assert client.login("ana", PASSWORD).status_code == 302
    page = client.get("/")
    assert b'href="/account"' in page.data  # linked from the top bar

    form = {"current_password": PASSWORD, "new_password": NEW_PASSWORD, "repeat": NEW_PASSWORD}
    wrong = client.post("/account", data={**form, "current_password": "not my password"})
    assert wrong.status_code == 401 and b"This is not your current password." in wrong.data
    weak = client.post("/account", data={**form, "new_password": "password", "repeat": "password"})
    assert weak.status_code == 400 and b"at least 10 characters" in weak.data
    common = client.post("/account", data={**form, "new_password": "qwertyuiop", "repeat": "qwertyuiop"})
    assert common.status_code == 400 and b"top-100 common password" in common.data
    differ = client.post("/account", data={**form, "repeat": "something else"})
    assert differ.status_code == 400 and b"The two new passwords differ." in differ.data
    assert other.get("/api/activities").status_code == 200  # nothing changed yet

    done = client.post("/account", data=form)
    assert done.status_code == 302 and done.headers["Location"] == "/account"
    assert client.get("/api/activities").status_code == 200  # this session goes on
    assert other.get("/api/activities").status_code == 401  # every other one has ended
    fresh = app.test_client()
    assert fresh.login("ana", PASSWORD).status_code == 401
    assert fresh.login("ana", NEW_PASSWORD).status_code == 302


def test_wrong_current_passwords_are_throttled(app_with, make_user):
    app = app_with(RATELIMIT_FAILURES=2, RATELIMIT_WINDOW="1 hour")
    client = app.test_client()
    make_user("annotator", "ana")
    assert client.login("ana", PASSWORD).status_code == 302
    form = {"current_password": "guess", "new_password": NEW_PASSWORD, "repeat": NEW_PASSWORD}
    assert [client.post("/account", data=form).status_code for _ in range(3)] == [401, 401, 429]


def test_participants_have_no_account_page(client, make_user):
    client.login_as(make_user("participant", "p-1"))
    assert client.get("/account").status_code == 403


# The admin's Users page


def test_the_users_page_lists_staff_with_role_status_and_last_sign_in(app, admin_client, make_user):
    make_user("annotator", "ana")
    make_user("participant", "p-1")
    page = admin_client.get("/users/")
    assert page.status_code == 200
    rows = dict(re.findall(rb'<tr data-user="([^"]+)">(.*?)</tr>', page.data, re.S))
    assert set(rows) == {b"admin", b"ana"}  # participants belong to their study
    assert b'value="annotator" selected' in rows[b"ana"] and b"Deactivate" in rows[b"ana"]
    assert b"UTC" in rows[b"admin"].split(b"</time>")[-2]  # admin has signed in: a last sign-in time
    assert b'href="/users/"' in page.data  # in the navigation
    assert b'href="/users/"' not in signed_in(app, "ana").get("/").data


def test_an_admin_creates_a_user_and_sees_the_password_once(app, admin_client):
    response = admin_client.post("/users/", data={"username": "mia", "role": "reviewer"})
    assert response.status_code == 200 and response.headers["Cache-Control"] == "no-store"
    password = shown_password(response)
    assert signed_in(app, "mia", password).get("/api/activities").status_code == 200
    assert user_named(app, "mia").role is Role.REVIEWER
    again = admin_client.post("/users/", data={"username": "mia", "role": "annotator"})
    assert again.status_code == 400 and b"already exists" in again.data
    bad = admin_client.post("/users/", data={"username": "zed", "role": "participant"})
    assert bad.status_code == 400 and b"Not a valid choice" in bad.data


def test_a_new_role_applies_at_once_and_ends_the_sessions(app, admin_client, make_user):
    ana = make_user("annotator", "ana")
    browser = signed_in(app, "ana")
    assert browser.get("/studies/").status_code == 403
    response = admin_client.post(f"/users/{ana.id}/role", data={"role": "admin"})
    assert response.status_code == 302
    assert browser.get("/api/activities").status_code == 401  # signed out
    assert signed_in(app, "ana").get("/studies/").status_code == 200  # and an admin now
    refused = admin_client.post(f"/users/{ana.id}/role", data={"role": "participant"})
    assert refused.status_code == 400 and refused.get_data(as_text=True).count("Not a valid choice") == 1


def test_deactivation_ends_the_sessions_at_once_and_activation_undoes_it(app, admin_client, make_user):
    ana = make_user("annotator", "ana")
    browser = signed_in(app, "ana")
    assert admin_client.post(f"/users/{ana.id}/deactivate").status_code == 302
    assert browser.get("/api/activities").status_code == 401
    assert app.test_client().login("ana", PASSWORD).status_code == 401
    assert b"deactivated" in admin_client.get("/users/").data
    assert admin_client.post(f"/users/{ana.id}/activate").status_code == 302
    assert signed_in(app, "ana").get("/api/activities").status_code == 200
    with app.app_context():
        assert db.session.get(User, ana.id) is not None  # never deleted


def test_a_password_reset_shows_a_new_one_once_and_ends_the_sessions(app, admin_client, make_user):
    ana = make_user("annotator", "ana")
    browser = signed_in(app, "ana")
    response = admin_client.post(f"/users/{ana.id}/password")
    assert response.status_code == 200 and response.headers["Cache-Control"] == "no-store"
    password = shown_password(response)
    assert browser.get("/api/activities").status_code == 401
    assert app.test_client().login("ana", PASSWORD).status_code == 401
    assert signed_in(app, "ana", password).get("/api/activities").status_code == 200
    assert password.encode() not in admin_client.get("/users/").data


def test_the_last_active_admin_stays_an_active_admin(app, admin_client, make_user):
    admin = user_named(app, "admin")
    for url, data in ((f"/users/{admin.id}/deactivate", {}), (f"/users/{admin.id}/role", {"role": "annotator"})):
        refused = admin_client.post(url, data=data)
        assert refused.status_code == 400 and b"the last active admin" in refused.data
    assert admin_client.get("/users/").status_code == 200  # still signed in, still admin
    # With a second admin, the first may step down (and is signed out by it).
    make_user("admin", "deputy")
    assert admin_client.post(f"/users/{admin.id}/role", data={"role": "reviewer"}).status_code == 302
    assert admin_client.get("/users/").status_code == 302
    assert user_named(app, "admin").role is Role.REVIEWER


def test_participants_are_not_managed_on_the_users_page(admin_client, make_user):
    person = make_user("participant", "p-1")
    staff = make_user("annotator", "ana")
    assert admin_client.post(f"/users/{staff.id}/deactivate").status_code == 302
    for action in ("deactivate", "activate", "password"):
        assert admin_client.post(f"/users/{person.id}/{action}").status_code == 404
    assert admin_client.post(f"/users/{person.id}/role", data={"role": "admin"}).status_code == 404


# The commands


def test_users_command_lists_staff(ctx, runner):
    users.create_user("ana", Role.ANNOTATOR)
    users.create_user("p-1", Role.PARTICIPANT)
    result = runner.invoke(args=["egonet", "users"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].split() == ["NAME", "ROLE", "STATUS", "CREATED", "LAST", "SIGN-IN"]
    assert len(lines) == 2 and lines[1].split()[:3] == ["ana", "annotator", "active"]


def test_role_and_activation_commands(ctx, runner):
    ana, _ = users.create_user("ana", Role.ANNOTATOR)
    token = ana.session_token
    result = runner.invoke(args=["egonet", "set-role", "ana", "reviewer"])
    assert result.exit_code == 0 and "'ana' is now reviewer" in result.output
    assert ana.role is Role.REVIEWER and ana.session_token != token

    token = ana.session_token
    assert runner.invoke(args=["egonet", "deactivate", "ana"]).exit_code == 0
    assert not ana.active and ana.session_token != token
    assert runner.invoke(args=["egonet", "activate", "ana"]).exit_code == 0 and ana.active

    for args, code, message in [
        (["set-role", "ana", "participant"], 2, "ROLE"),
        (["set-role", "nobody", "admin"], 1, "no user named 'nobody'"),
        (["deactivate", "nobody"], 1, "no user named 'nobody'"),
    ]:
        result = runner.invoke(args=["egonet", *args])
        assert result.exit_code == code and message in result.output, (args, result.output)


def test_the_commands_keep_the_last_active_admin(ctx, runner):
    users.create_user("root", Role.ADMIN)
    for args in (["deactivate", "root"], ["set-role", "root", "annotator"]):
        result = runner.invoke(args=["egonet", *args])
        assert result.exit_code == 1 and result.output.strip() == "Error: 'root' is the last active admin; make another user admin first"


def test_set_password_command(ctx, runner):
    ana, _ = users.create_user("ana", Role.ANNOTATOR)
    token = ana.session_token
    result = runner.invoke(args=["egonet", "set-password", "ana"])
    assert result.exit_code == 0, result.output
    generated = result.output.split("password: ")[1].strip()
    assert check_password_hash(ana.password_hash, generated) and ana.session_token != token
    result = runner.invoke(args=["egonet", "set-password", "ana", "--password", NEW_PASSWORD])
    assert result.exit_code == 0 and "password:" not in result.output
    assert check_password_hash(ana.password_hash, NEW_PASSWORD)
    result = runner.invoke(args=["egonet", "set-password", "ana", "--password", "qwertyuiop"])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1 and "top-100 common password" in result.output
    users.create_user("p-1", Role.PARTICIPANT)
    result = runner.invoke(args=["egonet", "set-password", "p-1"])
    assert result.exit_code == 1 and "participants have no password" in result.output


def test_create_user_reset_password(ctx, runner):
    result = runner.invoke(args=["egonet", "create-user", "root", "--role", "admin", "--reset-password"])
    assert result.exit_code == 0 and "created admin 'root'" in result.output  # missing: created
    first = result.output.split("password: ")[1].strip()
    root = users.find_user("root")
    token = root.session_token
    result = runner.invoke(args=["egonet", "create-user", "root", "--reset-password"])
    assert result.exit_code == 0, result.output
    second = result.output.split("password: ")[1].strip()
    assert second != first and check_password_hash(root.password_hash, second) and root.session_token != token
    for args, code, message in [
        (["root", "--role", "annotator", "--reset-password"], 1, "'root' is admin, not annotator"),
        (["root", "--if-missing", "--reset-password"], 2, "give one of them"),
        (["newcomer"], 2, "Missing option '--role'"),
        (["root", "--role", "admin", "--password", "qwertyuiop"], 1, "already exists"),
        (["newcomer", "--role", "admin", "--password", "qwertyuiop"], 1, "top-100 common password"),
    ]:
        result = runner.invoke(args=["egonet", "create-user", *args])
        assert result.exit_code == code and message in result.output, (args, result.output)


# The migration


def test_the_migration_gives_every_existing_user_their_own_token(ctx):
    downgrade(revision="0004")
    try:
        with db.engine.begin() as conn:
            for name in ("ana", "bea"):
                conn.execute(
                    sa.text("INSERT INTO \"user\" (username, role, active, created_at) VALUES (:n, 'annotator', :a, :t)"),
                    {"n": name, "a": True, "t": "2024-01-01 00:00:00"},
                )
    finally:
        upgrade()
    tokens = [user.session_token for user in db.session.execute(db.select(User)).scalars()]
    assert len(tokens) == 2 and len(set(tokens)) == 2 and all(len(token) >= 40 for token in tokens)
