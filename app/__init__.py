"""EgoNet Studio: label action-objects, run human studies, train and score EgoNet.

``create_app`` follows Flask's tutorial: defaults, then ``instance/config.py``
if present, then ``FLASK_*`` environment variables (for example
``FLASK_SQLALCHEMY_DATABASE_URI``), then the test mapping. It never creates
or migrates tables: ``flask db upgrade`` does that.
"""

import os
from pathlib import Path

from flask import Flask

DEV_SECRET_KEY = "dev-only-change-me"


def normalise_database_url(url: str) -> str:
    """Use the psycopg (3) driver for plain ``postgresql://`` URLs."""
    for prefix in ("postgres://", "postgresql://"):
        if url.startswith(prefix):
            return "postgresql+psycopg://" + url[len(prefix) :]
    return url


def create_app(test_config: dict | None = None) -> Flask:
    app = Flask(
        __name__,
        instance_relative_config=True,
        template_folder="../templates",
        static_folder="../static",
    )
    instance = Path(app.instance_path)
    app.config.from_mapping(
        SECRET_KEY=DEV_SECRET_KEY,
        SQLALCHEMY_DATABASE_URI=f"sqlite:///{instance / 'egonet.sqlite3'}",
        SQLALCHEMY_ENGINE_OPTIONS={"pool_pre_ping": True},
        MEDIA_ROOT=str(instance / "media"),
        CACHE_ROOT=str(instance / "cache"),
        MAX_CONTENT_LENGTH=64 * 1024 * 1024,
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Lax",
        WTF_CSRF_HEADERS=["X-CSRFToken", "X-CSRF-Token"],
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

    from app.extensions import csrf, db, login_manager, migrate

    db.init_app(app)
    migrate.init_app(app, db, directory=str(Path(app.root_path).parent / "migrations"), render_as_batch=True)
    csrf.init_app(app)
    login_manager.init_app(app)
    login_manager.login_view = "auth.login"

    from app import errors, security
    from app.blueprints import api, auth, frames, label, navigation, scores, studies, study, training
    from app.cli import bp as cli_bp

    security.require_production_safety(app)
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
