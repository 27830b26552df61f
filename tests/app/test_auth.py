import os
import re
import time
import uuid
from datetime import UTC, datetime, timedelta
from email.utils import parsedate_to_datetime
from types import SimpleNamespace

import pytest

from app import create_app
from tests.app.conftest import PASSWORD


def test_pages_need_a_sign_in(client):
    response = client.get("/activities/1")
    assert response.status_code == 302 and "/login?next=/activities/1" in response.headers["Location"]
    api = client.get("/api/activities")
    assert api.status_code == 401 and api.get_json()["error"] == "unauthorized"


def test_sign_in_then_out(client, make_user):
    make_user("annotator", "ana")
    response = client.post("/login?next=/api/activities", data={"username": "ana", "password": PASSWORD})
    assert response.status_code == 302 and response.headers["Location"] == "/api/activities"
    assert client.get("/api/activities").status_code == 200
    assert client.post("/logout").status_code == 302
    assert client.get("/api/activities").status_code == 401


@pytest.mark.parametrize("username, password", [("ana", "wrong password"), ("nobody", PASSWORD), ("pat", PASSWORD)])
def test_bad_credentials_and_participants_cannot_sign_in(client, make_user, username, password):
    make_user("annotator", "ana")
    make_user("participant", "pat")
    response = client.post("/login", data={"username": username, "password": password})
    assert response.status_code == 401 and b"wrong password" in response.data
    assert client.get("/api/activities").status_code == 401


def test_open_redirects_are_refused(client, make_user):
    make_user("admin", "root")
    response = client.post("/login?next=//evil.example/x", data={"username": "root", "password": PASSWORD})
    assert response.headers["Location"] == "/"


def test_csrf_is_enforced_for_forms_and_fetch(client, make_user):
    make_user("admin", "root")
    refused = client.post("/login", data={"username": "root", "password": PASSWORD}, csrf=False)
    assert refused.status_code == 400 and b"CSRF" in refused.data
    api = client.post("/logout", csrf=False, headers={"Accept": "application/json"})
    assert api.status_code == 400 and "CSRF" in api.get_json()["message"]


def test_session_cookie_flags(client, make_user):
    make_user("admin", "root")
    response = client.login("root", PASSWORD)
    cookie = response.headers["Set-Cookie"]
    assert "HttpOnly" in cookie and "SameSite=Lax" in cookie


def test_production_refuses_a_short_key(tmp_path):
    with pytest.raises(RuntimeError, match="SECRET_KEY"):
        create_app({"PRODUCTION": True, "SECRET_KEY": "dev-only-change-me"}, instance_path=str(tmp_path))
    app = create_app({"PRODUCTION": True, "SECRET_KEY": "x" * 40, "SQLALCHEMY_DATABASE_URI": "sqlite://"},
                     instance_path=str(tmp_path))
    assert app.config["SESSION_COOKIE_SECURE"] is True


def test_signed_out_participant_pages_lead_to_the_study_entry(client):
    response = client.get("/s/trials")
    assert response.status_code == 302 and response.headers["Location"] == "/s/"
    assert client.get("/studies/").headers["Location"].startswith("/login")


def test_html_forms_refuse_json_bodies(app, admin_client):
    """Flask-WTF would fill forms from JSON, where nested values crash the fields (a 500): a form's
    address takes no JSON (415, app.validation.check_request)."""
    forms = [rule.rule for rule in app.url_map.iter_rules() if rule.endpoint in ("auth.login", "studies.create", "training.start")]
    assert len(forms) == 3
    for url in forms:
        for body in ({"username": ["a", "b"], "epochs": {"x": 1}, "name": 5}, {"model": None}):
            with admin_client.post(url, json=body, headers={"Accept": "application/json"}) as response:
                assert response.status_code == 415 and response.get_json()["error"] == "unsupported_media_type", url


def test_a_session_cookie_copied_before_log_out_is_refused_after(app, client, make_user):
    make_user("annotator", "ana")
    assert client.login("ana", PASSWORD).status_code == 302
    copied = client.get_cookie("session").value
    assert client.post("/logout").status_code == 302
    thief = app.test_client()
    thief.set_cookie("session", copied)
    assert thief.get("/api/activities").status_code == 401
    # The same user signing in again gets a session that works (a new token).
    assert client.login("ana", PASSWORD).status_code == 302
    assert client.get("/api/activities").status_code == 200


def test_remember_me_cookie_flags_and_it_ends_at_log_out(app, client, make_user):
    make_user("annotator", "ana")
    response = client.post("/login", data={"username": "ana", "password": PASSWORD, "remember": "y"})
    cookie = next(c for c in response.headers.getlist("Set-Cookie") if c.startswith("remember_token="))
    assert "HttpOnly" in cookie and "SameSite=Lax" in cookie
    expires = parsedate_to_datetime(re.search(r"Expires=([^;]+)", cookie).group(1))
    assert timedelta(days=1) < expires - datetime.now(UTC) <= timedelta(days=30)
    remembered = client.get_cookie("remember_token").value

    fresh = app.test_client()  # a new browser with only the remember-me cookie: signed in
    fresh.set_cookie("remember_token", remembered)
    assert fresh.get("/api/activities").status_code == 200
    assert client.post("/logout").status_code == 302
    stale = app.test_client()
    stale.set_cookie("remember_token", remembered)
    assert stale.get("/api/activities").status_code == 401


def test_sign_in_starts_a_new_session_with_a_new_csrf_token(client, make_user):
    make_user("annotator", "ana")
    before = client.fetch_csrf_token()
    with client.session_transaction() as session:
        planted_token = session["csrf_token"]
        session["planted"] = "by someone else"  # session fixation: state set before log-in
    assert client.login("ana", PASSWORD).status_code == 302
    with client.session_transaction() as session:
        assert "planted" not in session and session.get("csrf_token") != planted_token
    refused = client.post("/logout", headers={"X-CSRFToken": before})
    assert refused.status_code == 400
    assert client.post("/logout").status_code == 302  # with the new page's token


def test_an_account_without_a_password_never_signs_in(ctx, client):
    """Imported mask authors have no password; reactivated, the dummy hash's secret must not let them in."""
    from app.extensions import db
    from app.models import Role, User

    db.session.add(User(username="import", role=Role.ANNOTATOR, password_hash=None, active=True))
    db.session.commit()
    assert client.login("import", "not-a-real-password").status_code == 401


def test_wrong_passwords_are_throttled_per_account_and_address(app_with, make_user):
    app = app_with(RATELIMIT_FAILURES=3, RATELIMIT_WINDOW="1 hour")
    client = app.test_client()
    make_user("annotator", "ana")
    make_user("annotator", "bea")
    for _ in range(3):
        assert client.login("ana", "wrong password").status_code == 401
    locked = client.login("ana", "wrong password")
    assert locked.status_code == 429 and b"Too many failed attempts" in locked.data and b"<html" in locked.data
    assert 3500 <= int(locked.headers["Retry-After"]) <= 3600
    assert client.login("ana", PASSWORD).status_code == 429  # a correct password waits too
    api = client.post("/login", data={"username": "ana", "password": PASSWORD}, headers={"Accept": "application/json"})
    assert api.status_code == 429 and api.get_json()["error"] == "too_many_requests"
    assert re.search(r"Try again in (59|60) minutes", api.get_json()["message"]) and "Retry-After" in api.headers

    # Another account from the same address, and the same account from elsewhere, are not locked out.
    assert client.login("bea", "wrong password").status_code == 401
    assert client.login("bea", PASSWORD).status_code == 302
    elsewhere = app.test_client()
    elsewhere.environ_base["REMOTE_ADDR"] = "10.0.0.7"
    assert elsewhere.login("ana", PASSWORD).status_code == 302
    # The page itself stays reachable.
    assert client.get("/login").status_code == 200


def test_the_thirtieth_wrong_password_is_refused_with_the_defaults(app_with, make_user):
    app = app_with()
    client = app.test_client()
    make_user("annotator", "ana")
    statuses = [client.login("ana", "wrong password").status_code for _ in range(30)]
    assert statuses[-1] == 429 and set(statuses) == {401, 429}
    assert statuses.index(429) == app.config["RATELIMIT_FAILURES"]


def test_a_success_ends_a_run_of_failures(app_with, make_user):
    app = app_with(RATELIMIT_FAILURES=3, RATELIMIT_WINDOW="1 hour")
    client = app.test_client()
    make_user("annotator", "ana")
    for _ in range(2):
        assert client.login("ana", "wrong password").status_code == 401
    assert client.login("ana", PASSWORD).status_code == 302
    assert client.post("/logout").status_code == 302
    assert [client.login("ana", "wrong password").status_code for _ in range(4)] == [401, 401, 401, 429]


def test_the_lock_out_ends_with_its_window(app_with, make_user, monkeypatch):
    import limits.storage.memory

    app = app_with(RATELIMIT_FAILURES=2, RATELIMIT_WINDOW="15 minutes")
    client = app.test_client()
    make_user("annotator", "ana")
    for _ in range(2):
        client.login("ana", "wrong password")
    assert client.login("ana", PASSWORD).status_code == 429
    later = time.time() + 15 * 60 + 1
    monkeypatch.setattr(limits.storage.memory, "time", SimpleNamespace(time=lambda: later))
    assert client.login("ana", PASSWORD).status_code == 302


def test_an_app_with_the_limiter_off_leaves_it_on_for_the_next(app_with, make_user):
    """Flask-Limiter keeps its switch on its one object; each app sets it (tests make many apps)."""
    from app.throttle import limiter

    app_with(RATELIMIT_ENABLED=False)
    assert not limiter.enabled
    app = app_with(RATELIMIT_FAILURES=1)
    client = app.test_client()
    make_user("annotator", "ana")
    assert [client.login("ana", "wrong password").status_code for _ in range(2)] == [401, 429]


@pytest.mark.skipif(not os.environ.get("EGONET_TEST_REDIS_URL"), reason="EGONET_TEST_REDIS_URL not set")
def test_log_in_throttle_on_redis(app_with, make_user):
    import redis

    url = os.environ["EGONET_TEST_REDIS_URL"]
    app = app_with(RATELIMIT_STORAGE_URI=url, RATELIMIT_FAILURES=2, RATELIMIT_WINDOW="1 hour")
    client = app.test_client()
    name = f"ana-{uuid.uuid4().hex[:8]}"  # keys of this run only, on a shared server
    make_user("annotator", name)
    server = redis.Redis.from_url(url)
    try:
        assert [client.login(name, "wrong password").status_code for _ in range(3)] == [401, 401, 429]
        keys = server.keys(f"*/{name}/*")
        assert len(keys) == 1 and int(server.get(keys[0])) == 2  # the count lives in Redis, shared by every process
        assert client.login(name, PASSWORD).status_code == 429
        server.expire(keys[0], 1)  # end the window early
        time.sleep(1.2)
        assert client.login(name, PASSWORD).status_code == 302
    finally:
        for key in server.keys(f"*/{name}/*"):
            server.delete(key)
