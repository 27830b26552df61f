"""The key that signs cookies: never a constant from the code.

Started the README's way (no FLASK_SECRET_KEY), the app makes a random key
on first start and keeps it in the instance folder (mode 0600); a cookie
signed with any key from the source, the old development constant among
them, is refused.
"""

import os
import stat

from flask.sessions import SecureCookieSessionInterface

from app import create_app
from app.limits import SECRET_KEY_FILE


def forged_session_cookie(app, secret_key: str, session: dict) -> str:
    """A session cookie as an attacker would sign it with ``secret_key``."""
    original = app.secret_key
    app.secret_key = secret_key
    try:
        return SecureCookieSessionInterface().get_signing_serializer(app).dumps(session)
    finally:
        app.secret_key = original


def test_a_fresh_instance_makes_a_random_key_and_keeps_it(tmp_path, monkeypatch):
    monkeypatch.delenv("FLASK_SECRET_KEY", raising=False)
    first = create_app(instance_path=str(tmp_path / "a"))
    path = tmp_path / "a" / SECRET_KEY_FILE
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert len(first.secret_key) >= 64 and first.secret_key == path.read_text().strip()
    assert create_app(instance_path=str(tmp_path / "a")).secret_key == first.secret_key  # reused
    assert create_app(instance_path=str(tmp_path / "b")).secret_key != first.secret_key  # random


def test_an_explicit_key_wins(tmp_path, monkeypatch):
    monkeypatch.setenv("FLASK_SECRET_KEY", "k" * 48)
    app = create_app(instance_path=str(tmp_path))
    assert app.secret_key == "k" * 48
    assert not (tmp_path / SECRET_KEY_FILE).exists()


def test_a_cookie_forged_with_the_old_constant_is_refused(app_with, make_user):
    app = app_with(SECRET_KEY=None)
    admin = make_user("admin", "admin")
    client = app.test_client()
    for key in ("dev-only-change-me", "test-secret"):
        cookie = forged_session_cookie(app, key, {"_user_id": admin.get_id(), "_fresh": True})
        client.set_cookie("session", cookie)
        response = client.get("/label/")
        assert response.status_code == 302 and "/login" in response.headers["Location"], key
    # The same session signed with the instance's own key gets in (so the check above is meaningful).
    client.set_cookie("session", forged_session_cookie(app, app.secret_key, {"_user_id": admin.get_id(), "_fresh": True}))
    assert client.get("/label/").status_code == 200
