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


def test_html_forms_ignore_json_bodies(app, admin_client):
    """Flask-WTF would fill forms from JSON, where nested values crash the fields (a 500)."""
    forms = [rule.rule for rule in app.url_map.iter_rules() if rule.endpoint in ("auth.login", "studies.create", "training.start")]
    assert len(forms) == 3
    for url in forms:
        for body in ({"username": ["a", "b"], "epochs": {"x": 1}, "name": 5}, {"model": None}):
            with admin_client.post(url, json=body) as response:
                assert response.status_code == 400, (url, response.status_code)
