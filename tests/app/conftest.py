"""Fixtures for tests that need the app and a database (Flask's tutorial style).

Every test using ``app`` runs on SQLite and, when ``EGONET_TEST_POSTGRES_URL``
is set (for example ``postgresql://postgres@127.0.0.1:5432/test``), on
PostgreSQL too. Each backend is migrated once per session with ``flask db
upgrade`` (in a private schema on PostgreSQL); each test gets empty tables
and its own media folder.
"""

import os
import uuid

import pytest
import sqlalchemy as sa
from flask_migrate import upgrade

from app import create_app, normalise_database_url
from app.extensions import db

POSTGRES_URL = os.environ.get("EGONET_TEST_POSTGRES_URL")
BACKENDS = ["sqlite"] + (["postgresql"] if POSTGRES_URL else [])


def make_app(database_url: str, tmp_path, **overrides):
    config = {
        "TESTING": True,
        "SECRET_KEY": "test-secret",
        "SQLALCHEMY_DATABASE_URI": database_url,
        "MEDIA_ROOT": str(tmp_path / "media"),
        "CACHE_ROOT": str(tmp_path / "cache"),
        "SERVER_NAME": None,
    }
    config.update(overrides)
    return create_app(config)


@pytest.fixture(scope="session", params=BACKENDS)
def database_url(request, tmp_path_factory):
    """A migrated, empty database for the whole session."""
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path_factory.mktemp('db') / 'test.sqlite3'}"
        schema = None
    else:
        schema = f"test_{uuid.uuid4().hex[:12]}"
        base = normalise_database_url(POSTGRES_URL)
        engine = sa.create_engine(base)
        with engine.begin() as conn:
            conn.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
        engine.dispose()
        sep = "&" if "?" in base else "?"
        url = f"{base}{sep}options=-csearch_path%3D{schema}"
    app = make_app(url, tmp_path_factory.mktemp("migrate"))
    with app.app_context():
        upgrade()
        db.engine.dispose()
    yield url
    if schema:
        engine = sa.create_engine(normalise_database_url(POSTGRES_URL))
        with engine.begin() as conn:
            conn.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
        engine.dispose()


@pytest.fixture
def app(database_url, tmp_path):
    app = make_app(database_url, tmp_path)
    with app.app_context():
        yield app
        db.session.remove()
        with db.engine.begin() as conn:
            for table in reversed(db.metadata.sorted_tables):
                conn.execute(table.delete())
        db.engine.dispose()


@pytest.fixture
def client(app):
    return app.test_client()


@pytest.fixture
def runner(app):
    return app.test_cli_runner()
