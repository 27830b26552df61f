"""EgoNet Studio: label action-objects, run human studies, train and score EgoNet.

``create_app`` follows Flask's tutorial: defaults, then ``instance/config.py``
if present, then ``FLASK_*`` environment variables (for example
``FLASK_SQLALCHEMY_DATABASE_URI``), then the test mapping. It never creates
or migrates tables: ``flask db upgrade`` does that.
"""

import os
import secrets
from pathlib import Path

from flask import Flask
from werkzeug.routing import IntegerConverter

# Path ids are at most this (SQL BIGINT): larger ones match no route (404).
MAX_ID = 2**63 - 1
SECRET_KEY_FILE = "secret_key"
MIN_SECRET_KEY_LENGTH = 32


class IdConverter(IntegerConverter):
    """``<int:...>`` in URLs: a non-negative integer that fits a 64-bit column."""

    def __init__(self, map, *args, **kwargs):
        kwargs.setdefault("max", MAX_ID)
        super().__init__(map, *args, **kwargs)


def instance_secret_key(instance: Path) -> str:
    """The key that signs cookies when none is configured: 32 random bytes
    (hex) made on first start, kept in the instance folder with mode 0600 and
    reused afterwards. Processes starting together agree: the first file
    linked into place wins."""
    path = instance / SECRET_KEY_FILE
    if not path.exists():
        draft = instance / f".{SECRET_KEY_FILE}.{os.getpid()}.{secrets.token_hex(4)}"
        with os.fdopen(os.open(draft, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600), "w") as handle:
            handle.write(secrets.token_hex(32) + "\n")
        try:
            os.link(draft, path)
        except FileExistsError:
            pass
        finally:
            draft.unlink()
    key = path.read_text().strip()
    if len(key) < MIN_SECRET_KEY_LENGTH:
        raise RuntimeError(f"{path}: the secret key is shorter than {MIN_SECRET_KEY_LENGTH} characters; delete the file")
    return key


def normalise_database_url(url: str) -> str:
    """Use the psycopg (3) driver for plain ``postgresql://`` URLs."""
    for prefix in ("postgres://", "postgresql://"):
        if url.startswith(prefix):
            return "postgresql+psycopg://" + url[len(prefix) :]
    return url


def create_app(test_config: dict | None = None, *, instance_path: str | None = None) -> Flask:
    app = Flask(
        __name__,
        instance_path=instance_path,
        instance_relative_config=True,
        template_folder="../templates",
        static_folder="../static",
    )
    instance = Path(app.instance_path)
    app.url_map.converters["int"] = IdConverter
    app.config.from_mapping(
        SECRET_KEY=None,
        SQLALCHEMY_DATABASE_URI=f"sqlite:///{instance / 'egonet.sqlite3'}",
        SQLALCHEMY_ENGINE_OPTIONS={"pool_pre_ping": True},
        MEDIA_ROOT=str(instance / "media"),
        CACHE_ROOT=str(instance / "cache"),
        MAX_CONTENT_LENGTH=64 * 1024 * 1024,
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Lax",
        WTF_CSRF_HEADERS=["X-CSRFToken", "X-CSRF-Token"],
        # The token is bound to the session (which ends at log-out), not to
        # the clock: a page left open for hours can still save.
        WTF_CSRF_TIME_LIMIT=None,
        FRAMES_PER_PAGE=120,
        PRODUCTION=False,
    )
    if test_config is None:
        app.config.from_pyfile("config.py", silent=True)
        app.config.from_prefixed_env()
    else:
        app.config.from_mapping(test_config)
    app.config["SQLALCHEMY_DATABASE_URI"] = normalise_database_url(app.config["SQLALCHEMY_DATABASE_URI"])
    os.makedirs(app.instance_path, exist_ok=True)
    if not app.config.get("SECRET_KEY"):
        app.config["SECRET_KEY"] = instance_secret_key(instance)

    from app.extensions import csrf, db, login_manager, migrate

    db.init_app(app)
    migrate.init_app(app, db, directory=str(Path(app.root_path).parent / "migrations"), render_as_batch=True)
    csrf.init_app(app)
    login_manager.init_app(app)
    login_manager.login_view = "auth.login"

    from app import errors, security, throttle
    from app.blueprints import api, auth, frames, label, navigation, scores, studies, study, training
    from app.cli import bp as cli_bp

    security.require_production_safety(app)
    throttle.init_app(app)
    errors.register(app)
    security.register(app)
    app.register_blueprint(auth.bp)
    for module in (frames, api, label, studies, study, training, scores):
        app.register_blueprint(module.bp)
    app.context_processor(navigation)
    app.register_blueprint(cli_bp)

    @login_manager.user_loader
    def load_user(user_id: str):
        from app.models import User

        return db.session.get(User, int(user_id)) if user_id.isdigit() else None

    return app
