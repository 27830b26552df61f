"""Fixtures for tests that need the app and a database (Flask's tutorial style).

Every test using ``app`` runs on SQLite and, when ``EGONET_TEST_POSTGRES_URL``
is set (for example ``postgresql://postgres@127.0.0.1:5432/test``), on
PostgreSQL too. Each backend is migrated once per session with ``flask db
upgrade`` (in a private schema on PostgreSQL); each test gets empty tables
and its own media folder.
"""

import copy
import os
import re
import uuid

import pytest
from flask.testing import FlaskClient
from flask_migrate import upgrade

from app import create_app
from app.extensions import db
from tests.system.harness import drop_schema, private_schema_url

POSTGRES_URL = os.environ.get("EGONET_TEST_POSTGRES_URL")
BACKENDS = ["sqlite"] + (["postgresql"] if POSTGRES_URL else [])


class CSRFClient(FlaskClient):
    """A test client that behaves like the app's pages: it fetches the CSRF
    token from a page's meta tag once, and sends it as a header with every
    state-changing request (CSRF stays on in tests). Signing in and out
    start a new session with a new token, so after a POST to those pages it
    fetches the token again, as the next page would carry it."""

    csrf_token: str | None = None
    NEW_SESSION_PATHS = ("/login", "/logout", "/account")

    def fetch_csrf_token(self) -> str:
        page = self.get("/login")
        self.csrf_token = re.search(rb'name="csrf-token" content="([^"]+)"', page.data).group(1).decode()
        return self.csrf_token

    def open(self, *args, **kwargs):
        method = kwargs.get("method", "GET").upper()
        if method not in ("GET", "HEAD", "OPTIONS") and kwargs.pop("csrf", True):
            headers = dict(kwargs.pop("headers", None) or {})
            headers.setdefault("X-CSRFToken", self.csrf_token or self.fetch_csrf_token())
            kwargs["headers"] = headers
        response = super().open(*args, **kwargs)
        if method == "POST" and args and isinstance(args[0], str) and args[0].startswith(self.NEW_SESSION_PATHS):
            self.csrf_token = None
        return response

    def login(self, username: str, password: str):
        return self.post("/login", data={"username": username, "password": password})

    def login_as(self, user) -> None:
        """Sign in without a password (participants have none): set Flask-Login's session key.

        It holds ``user.get_id()``, id and session token; the token is read
        from the database, so this works again after a log-out replaced it.
        """
        from app.models import User

        with self.application.app_context():
            user_id = db.session.get(User, user.id).get_id()
        with self.session_transaction() as session:
            session["_user_id"] = user_id
            session["_fresh"] = True


def make_app(database_url: str, tmp_path, **overrides):
    config = {
        "TESTING": True,
        "SECRET_KEY": "test-secret",
        "SQLALCHEMY_DATABASE_URI": database_url,
        "STORAGE_URL": str(tmp_path),
        "CACHE_ROOT": str(tmp_path / "cache"),
        "SERVER_NAME": None,
        # Jobs wait for a worker, as with Redis, unless a test asks for the in-process consumer.
        "QUEUE_IN_PROCESS": False,
    }
    config.update(overrides)
    app = create_app(config, instance_path=str(tmp_path / "instance"))
    app.test_client_class = CSRFClient
    return app


_RENDERED: dict[tuple, object] = {}


@pytest.fixture(autouse=True)
def demo_frames_rendered_once(monkeypatch):
    """``create_demo`` gets each synthetic frame rendered once a session, as a copy.

    ``synth.render_activity`` equals ``render_frame`` over indices ``0 ..
    count - 1``; rendering is most of a demo's cost and tests make demos by the
    hundred. ``renderer_truth`` and the renderer's own tests (tests/unit)
    still render for real.
    """
    from egonet import synth

    render_activity, render_frame = synth.render_activity, synth.render_frame

    def frame(activity, index, seed, width, height):
        key = (activity, index, seed, width, height)
        if key not in _RENDERED:
            _RENDERED[key] = render_frame(activity, index, seed=seed, width=width, height=height)
        return copy.deepcopy(_RENDERED[key])

    def rendered_once(activity, count, *, seed=0, width=320, height=240):
        render_activity(activity, count, seed=seed, width=width, height=height)  # refuses bad arguments as before
        return (frame(activity, index, seed, width, height) for index in range(count))

    monkeypatch.setattr(synth, "render_activity", rendered_once)


@pytest.fixture(scope="session")
def migrated_databases(tmp_path_factory):
    """Each backend's database, migrated on first use and kept for the session.

    pytest tears a session fixture down when its parameter changes; a worker
    that takes over the other backend's tests (pytest-xdist's worksteal) and
    back would otherwise migrate again at each switch.
    """
    urls, schemas = {}, []

    def migrated(backend: str) -> str:
        if backend in urls:
            return urls[backend]
        if backend == "sqlite":
            url = f"sqlite:///{tmp_path_factory.mktemp('db') / 'test.sqlite3'}"
        else:
            url, schema = private_schema_url(POSTGRES_URL)
            schemas.append(schema)
        app = make_app(url, tmp_path_factory.mktemp("migrate"))
        with app.app_context():
            upgrade()
            db.engine.dispose()
        urls[backend] = url
        return url

    yield migrated
    for schema in schemas:
        drop_schema(POSTGRES_URL, schema)


@pytest.fixture(scope="session", params=BACKENDS)
def database_url(request, migrated_databases):
    """A migrated, empty database for the whole session."""
    return migrated_databases(request.param)


def pytest_generate_tests(metafunc):
    """A test marked ``both_storages`` runs with its files in a folder and in a bucket."""
    if metafunc.definition.get_closest_marker("both_storages") and "storage_url" in metafunc.fixturenames:
        metafunc.parametrize("storage_url", ["local", "s3"], indirect=True)


@pytest.fixture
def storage_url(request, tmp_path):
    """Where the test app's files live: ``tmp_path`` (media/, checkpoints/, exports/ under it), or
    a fresh prefix in the SeaweedFS bucket for tests marked ``both_storages``."""
    if getattr(request, "param", "local") == "local":
        return str(tmp_path)
    request.getfixturevalue("seaweedfs")
    return f"s3://egonet-test/{uuid.uuid4().hex[:12]}"


@pytest.fixture
def app(database_url, storage_url, tmp_path):
    """The app on empty tables. Requests get their own app context, so ``g``
    and the database session never leak from one request into the next."""
    app = make_app(database_url, tmp_path, STORAGE_URL=storage_url)
    yield app
    with app.app_context():
        db.session.remove()
        with db.engine.begin() as conn:
            for table in reversed(db.metadata.sorted_tables):
                conn.execute(table.delete())
        db.engine.dispose()


@pytest.fixture
def app_with(database_url, tmp_path):
    """Make another app on the test's database with settings of its own, e.g.
    ``app_with(RATELIMIT_FAILURES=3)``; its connections close after the test."""
    made = []

    def make(**overrides):
        made.append(make_app(database_url, tmp_path, **overrides))
        return made[-1]

    yield make
    for other in made:
        other.extensions["egonet.queue"].stop_consumer()  # the in-process one, when a test turned it on
        with other.app_context():
            db.engine.dispose()


@pytest.fixture
def ctx(app):
    """An app context for tests that call services directly."""
    with app.app_context():
        yield app


@pytest.fixture
def client(app):
    return app.test_client()


@pytest.fixture
def runner(app):
    return app.test_cli_runner()


PASSWORD = "correct horse battery"


@pytest.fixture
def make_user(app):
    """Create a user with a role; staff get the password ``PASSWORD``."""
    from app.models import Role
    from app.services.users import create_user

    def make(role: str, username: str | None = None):
        role = Role(role)
        with app.app_context():
            user, _ = create_user(username or f"{role.value}-user", role, None if role is Role.PARTICIPANT else PASSWORD)
            db.session.refresh(user)
            db.session.expunge(user)
        return user

    return make


@pytest.fixture
def admin_client(client, make_user):
    make_user("admin", "admin")
    assert client.login("admin", PASSWORD).status_code == 302
    return client
