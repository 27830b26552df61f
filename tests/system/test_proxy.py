"""The review's probes of the documented deployment, through gunicorn: behind a proxy the throttles count clients.

The test client plays the TLS proxy: it sends ``X-Forwarded-For`` as nginx's
``$proxy_add_x_forwarded_for`` makes it (what the client sent, then the
address the proxy saw). With ``TRUSTED_PROXIES=1`` two clients behind it are
throttled apart and the admin is not locked out by a stranger; with 0 (no
proxy) the header is ignored, so forging it dodges nothing. On SQLite and,
when ``EGONET_TEST_POSTGRES_URL`` is set, on PostgreSQL.
"""

import os
import time
from contextlib import ExitStack, contextmanager

import httpx
import pytest
from flask_migrate import upgrade

from app.extensions import db
from app.models import Activity
from app.services import studies
from app.services.demo import create_demo
from app.services.users import create_user
from tests.system.harness import Server, csrf_token, drop_schema, make_app, private_schema_url

POSTGRES_URL = os.environ.get("EGONET_TEST_POSTGRES_URL")
PASSWORD = "proxy-test-password"
pytestmark = pytest.mark.slow


@pytest.fixture(params=["sqlite", *(["postgresql"] if POSTGRES_URL else [])])
def deployment(request, tmp_path):
    url, schema = private_schema_url(POSTGRES_URL) if request.param == "postgresql" else (f"sqlite:///{tmp_path / 'db.sqlite3'}", None)
    app = make_app(url, tmp_path)
    with app.app_context():
        upgrade()
        create_demo(frames_per_activity=2, seed=5, width=96, height=72)
        create_user("admin", "admin", PASSWORD)
        activity_ids = list(db.session.execute(db.select(Activity.id)).scalars())
        study = studies.create_study(name="proxy", activity_ids=activity_ids, frames_per_activity=1, seed=3)
        codes = [p.code for p in studies.add_participants(study, count=2)]
    yield {"url": url, "instance": tmp_path, "codes": codes}
    with app.app_context():
        db.session.remove()
        db.engine.dispose()
    if schema:
        drop_schema(POSTGRES_URL, schema)


@contextmanager
def serve(deployment, proxies: int):
    """gunicorn with ``TRUSTED_PROXIES=proxies``, and a maker of browsers behind the proxy (closed at the end)."""
    # One process: the log-in counts live in its memory (several processes share them through Redis).
    settings = {"TRUSTED_PROXIES": str(proxies), "RATELIMIT_ENTRY_FAILURES": "3"}
    server = Server(deployment["url"], deployment["instance"], workers=1, threads=4, settings=settings)
    with ExitStack() as clients:

        def behind_proxy(client_address: str, forged: str | None = None) -> httpx.Client:
            """A browser at ``client_address`` as the proxy saw it (``forged``: what it put in the header itself)."""
            chain = f"{forged}, {client_address}" if forged else client_address
            # Over HTTPS (as the proxy says) a browser's same-site Referer is required with the CSRF token.
            headers = {"X-Forwarded-For": chain, "X-Forwarded-Proto": "https", "Referer": f"https://127.0.0.1:{server.port}/"}
            return clients.enter_context(httpx.Client(base_url=server.url, headers=headers))

        try:
            yield behind_proxy
        finally:
            server.stop()


def log_in(client: httpx.Client, password: str) -> int:
    return client.post("/login", data={"username": "admin", "password": password, "csrf_token": csrf_token(client)}).status_code


def enter(client: httpx.Client, code: str) -> httpx.Response:
    return client.post("/s/?study=1", data={"code": code, "csrf_token": csrf_token(client, "/s/")})


def test_behind_one_trusted_proxy_clients_are_throttled_apart(deployment):
    with serve(deployment, proxies=1) as behind_proxy:
        started = time.monotonic()
        stranger = behind_proxy("203.0.113.5")
        # Review: 21 wrong passwords for admin locked the real admin out from any address.
        assert [log_in(stranger, "wrong password") for _ in range(21)] == [401] * 20 + [429]
        assert log_in(behind_proxy("198.51.100.7"), PASSWORD) == 302
        # Forging the header's first entries changes nothing: the proxy's own entry is the one read.
        assert log_in(behind_proxy("203.0.113.5", forged="192.0.2.99"), "wrong password") == 429
        # Review: one client's wrong codes locked codes (and the open link) for everyone behind the proxy.
        guesser = behind_proxy("203.0.113.5")
        assert [enter(guesser, "ZZZZZZZZ").status_code for _ in range(5)] == [401] * 4 + [429]
        assert enter(behind_proxy("198.51.100.7"), deployment["codes"][0]).headers["Location"].endswith("/s/consent")
        print(f"\nTRUSTED_PROXIES=1: 21 passwords + 2 sign-ins + 6 codes in {time.monotonic() - started:.1f} s")


def test_without_trusted_proxies_a_forged_header_dodges_nothing(deployment):
    with serve(deployment, proxies=0) as behind_proxy:
        started = time.monotonic()
        statuses = [log_in(behind_proxy(f"192.0.2.{i}"), "wrong password") for i in range(21)]
        assert statuses == [401] * 20 + [429]
        codes = [enter(behind_proxy(f"198.51.100.{i}"), "ZZZZZZZZ").status_code for i in range(5)]
        assert codes == [401] * 4 + [429]
        print(f"\nTRUSTED_PROXIES=0: 21 passwords + 5 codes with forged addresses in {time.monotonic() - started:.1f} s")
