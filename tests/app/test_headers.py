"""Security headers on every answer: every rule of the URL map, as every role (like the access matrix)."""

import pytest

from tests.app.access import ALL, all_url_values

CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; connect-src 'self'; "
    "object-src 'none'; base-uri 'self'; form-action 'self'; frame-ancestors 'none'"
)
# Media served behind the log-in: the matrix must see each of them answered, privately cached.
MEDIA = {"frames.media_file", "frames.thumbnail", "frames.depth", "label.annotation_mask", "label.instance_mask", "training.prediction_overlay"}


@pytest.fixture
def url_values(app, tmp_path):
    return all_url_values(app, tmp_path)


# The open link's pages, refusals included, which an MTurk HIT shows in a frame: MTurk's sites only may frame them.
FRAMED_BY_MTURK = {"study.open_link"}
MTURK_CSP = CSP.replace("frame-ancestors 'none'", "frame-ancestors https://workersandbox.mturk.com https://www.mturk.com")


def check_headers(response, endpoint: str, where: str) -> None:
    headers = response.headers
    framed = endpoint in FRAMED_BY_MTURK
    assert headers.get("Content-Security-Policy") == (MTURK_CSP if framed else CSP), where
    assert headers.get("X-Content-Type-Options") == "nosniff", where
    assert headers.get("X-Frame-Options") == (None if framed else "DENY"), where
    assert headers.get("Referrer-Policy") == "same-origin", where
    assert "Strict-Transport-Security" not in headers, where  # only in production
    cache = response.cache_control
    if endpoint.startswith("study."):  # the participant's pages, answers and frames
        assert headers.get("Cache-Control") == "no-store", where
    elif endpoint != "static" and "Cache-Control" in headers and not cache.no_store:
        assert cache.private and not cache.public, f"{where}: Cache-Control {headers['Cache-Control']}"


@pytest.mark.parametrize("role", [None, *sorted(ALL)])
def test_every_answer_carries_the_security_headers(app, client, make_user, url_values, role):
    user = make_user(role) if role is not None else None
    if user is not None:
        client.login_as(user)
    private_media = set()
    for rule in app.url_map.iter_rules():
        url = rule.build(url_values, append_unknown=False)[1]
        for method in sorted(rule.methods - {"OPTIONS"}):
            with client.open(url, method=method) as response:
                check_headers(response, rule.endpoint, f"{role} {method} {url}: {response.status_code}")
                if rule.endpoint in MEDIA and response.status_code == 200 and response.cache_control.private:
                    private_media.add(rule.endpoint)
            if rule.endpoint == "auth.logout" and user is not None:
                client.login_as(user)
    if role == "admin":
        assert private_media == MEDIA


def test_unknown_urls_and_static_files_carry_them_too(client):
    with client.get("/no/such/page") as missing:
        assert missing.status_code == 404
        check_headers(missing, "", "404")
    with client.get("/static/css/app.css") as static:
        assert static.status_code == 200
        check_headers(static, "static", "static")


def test_hsts_only_in_production(client, app_with):
    assert "Strict-Transport-Security" not in client.get("/login").headers
    production = app_with(PRODUCTION=True, SECRET_KEY="k" * 40)
    response = production.test_client().get("/login")
    assert response.headers["Strict-Transport-Security"] == "max-age=31536000"
    assert response.headers["Content-Security-Policy"] == CSP
