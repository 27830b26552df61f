"""CSRF tokens: bound to the session, not the clock; a stale one is refused by
name, and a page can fetch a fresh one."""

import time
from types import SimpleNamespace

import itsdangerous.timed
import pytest

from tests.app.test_labelling import body, make_frames, square

TOKEN_URL = "/api/csrf-token"


def fresh_token(client) -> str:
    response = client.get(TOKEN_URL)
    assert response.status_code == 200
    assert response.headers["Cache-Control"] == "no-store"
    return response.get_json()["csrf_token"]


def test_a_token_older_than_an_hour_still_saves(app, client, make_user, monkeypatch):
    frame_id, *_ = make_frames(app, n=1)
    client.login_as(make_user("annotator", "ann"))
    token = fresh_token(client)
    # Two hours later (itsdangerous reads the clock to date the token).
    later = time.time() + 2 * 3600
    monkeypatch.setattr(itsdangerous.timed, "time", SimpleNamespace(time=lambda: later))
    url = f"/api/label/frames/{frame_id}/annotation"
    saved = client.put(url, json=body(0, square(10, 30, 10, 40)), headers={"X-CSRFToken": token}, csrf=False)
    assert saved.status_code == 200, saved.get_json()
    assert saved.get_json()["version"] == 1


def test_a_token_from_another_session_is_refused_by_name(app, make_user):
    theirs, mine = app.test_client(), app.test_client()
    mine.login_as(make_user("annotator", "ann"))
    token = fresh_token(theirs)
    refused = mine.post("/logout", headers={"X-CSRFToken": token, "Accept": "application/json"}, csrf=False)
    assert refused.status_code == 400
    error = refused.get_json()
    assert error["error"] == "csrf" and "CSRF" in error["message"]
    assert set(error) == {"error", "message", "fields"}


def test_a_missing_token_is_refused_by_name(client):
    refused = client.post("/logout", headers={"Accept": "application/json"}, csrf=False)
    assert refused.status_code == 400
    assert refused.get_json()["error"] == "csrf"


@pytest.mark.parametrize("role", [None, "admin", "annotator", "participant"])
def test_the_fresh_token_works_for_everyone(app, client, make_user, role):
    if role is not None:
        client.login_as(make_user(role))
    token = fresh_token(client)
    # The token is accepted where a stale one is refused (400): log-out answers its redirect.
    assert client.post("/logout", headers={"X-CSRFToken": token}, csrf=False).status_code == 302


def test_a_fresh_token_replaces_one_the_session_no_longer_knows(app, client, make_user):
    client.login_as(make_user("annotator", "ann"))
    stale = fresh_token(client)
    with client.session_transaction() as session:
        del session["csrf_token"]  # as after the session was replaced in another tab
    refused = client.post("/logout", headers={"X-CSRFToken": stale, "Accept": "application/json"}, csrf=False)
    assert refused.status_code == 400 and refused.get_json()["error"] == "csrf"
    token = fresh_token(client)
    assert token != stale
    assert client.post("/logout", headers={"X-CSRFToken": token}, csrf=False).status_code == 302
