"""EgoNet Studio: label action-objects, run human studies, train and score EgoNet.

``create_app`` follows Flask's tutorial: defaults, then ``instance/config.py``
if present, then ``FLASK_*`` environment variables (for example
``FLASK_SQLALCHEMY_DATABASE_URI``), then the test mapping. It never creates
or migrates tables: ``flask db upgrade`` does that.
"""

import gc
import os
import secrets
from datetime import timedelta
from pathlib import Path

import cv2
import threadpoolctl
from flask import Flask
from werkzeug.middleware.proxy_fix import ProxyFix
from werkzeug.routing import BaseConverter, IntegerConverter

from app.limits import MAX_ID, MIN_SECRET_KEY_LENGTH, SECRET_KEY_FILE, TOKEN_REGEX



def digits_up_to(limit: int) -> str:
    """A regex for the decimal numbers from 0 to ``limit``: any with fewer
    digits, or as many with a smaller digit after a common start."""
    digits = str(limit)
    options = [rf"\d{{1,{len(digits) - 1}}}"] if len(digits) > 1 else []
    for i, d in enumerate(digits):
        if d != "0":
            options.append(rf"{digits[:i]}[0-{int(d) - 1}]\d{{{len(digits) - 1 - i}}}")
    return "(?:" + "|".join(options + [digits]) + ")"


class IdConverter(IntegerConverter):
    """``<int:...>`` in URLs: a non-negative integer that fits an id column.

    Its regex matches no larger number, so such a URL matches no route (404);
    a check after matching would answer 405 where another method shares the path.
    """

    regex = digits_up_to(MAX_ID)

    def __init__(self, map, *args, **kwargs):
        kwargs.setdefault("max", MAX_ID)
        super().__init__(map, *args, **kwargs)


class TokenConverter(BaseConverter):
    """``<token:...>`` in URLs: a link's token (``app.limits.TOKEN_REGEX``); another shape matches no route (404)."""

    regex = TOKEN_REGEX


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
    """Build the application: configuration, then extensions, then blueprints,
    the CLI and the error handlers.

    Args:
        test_config: settings applied last, in place of ``instance/config.py``
            and the ``FLASK_*`` environment variables.
        instance_path: the instance folder (Flask's default if not given).
    """
    app = Flask(
        __name__,
        instance_path=instance_path,
        instance_relative_config=True,
        template_folder="../templates",
        static_folder="../static",
    )
    app.url_map.converters["int"] = IdConverter
    app.url_map.converters["token"] = TokenConverter
    _configure(app, test_config)
    _init_extensions(app)
    _register(app)
    if not app.testing:
        # The ~150k objects made so far live as long as the process: out of
        # the cyclic garbage collector with them, whose full collections
        # otherwise scan them all (85-105 ms, in whichever request it falls).
        gc.freeze()
    return app


def _default_config(instance: Path) -> dict:
    """The settings every deployment starts from; the data live in ``instance``."""
    return dict(
        SECRET_KEY=None,
        SQLALCHEMY_DATABASE_URI=f"sqlite:///{instance / 'egonet.sqlite3'}",
        SQLALCHEMY_ENGINE_OPTIONS={"pool_pre_ping": True},
        # Where durable files live (app.services.storage): a folder, or
        # s3://bucket/prefix with the AWS_* variables for endpoint and keys.
        # Media under media/, checkpoints under checkpoints/, exports under exports/.
        STORAGE_URL=str(instance),
        # This host's own files: decoded frames, thumbnails, a bucket's cached copies.
        CACHE_ROOT=str(instance / "cache"),
        STORAGE_CACHE_BYTES=4 * 1024**3,
        # Files made from those on this host (thumbnails, depth previews, overlays, figures): at most so many bytes.
        DERIVED_CACHE_BYTES=1024**3,
        # Exports (app.services.exchange.jobs): one up to this many mask pixels
        # and without images is built in the request, bigger ones by the worker
        # into storage's exports/; at most EXPORT_MAX_PENDING waiting per person,
        # the EXPORT_KEEP most recent finished ones kept.
        EXPORT_INLINE_MAX_PIXELS=50_000_000,
        EXPORT_MAX_PENDING=2,
        EXPORT_KEEP=10,
        # Scoring (app.services.scoring.fitting): learned baselines whose
        # fitting and maps would take longer than this are scored by the worker.
        BASELINE_INLINE_S=20.0,
        # The frame page's fc7 activations (app.services.activations): drawn in
        # the request for models of at most this many parameters (egonet-lite),
        # by `flask egonet activations` for larger ones.
        ACTIVATIONS_INLINE_MAX_PARAMS=5_000_000,
        QUEUE_URL=os.environ.get("EGONET_QUEUE_URL") or f"sqlite:///{instance / 'queue.sqlite3'}",
        # With the SQLite queue the app runs its jobs itself, in a thread (app.queue):
        # no `flask egonet worker` needed on one machine. False: only a worker runs them.
        QUEUE_IN_PROCESS=True,
        # A running run whose worker has not renewed its lease for this long is taken for dead:
        # the next worker heartbeat queues it again (app.services.training.control).
        TRAINING_LEASE_S=300.0,
        MAX_CONTENT_LENGTH=64 * 1024 * 1024,
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Lax",
        WTF_CSRF_HEADERS=["X-CSRFToken", "X-CSRF-Token"],
        # The token is bound to the session (which ends at log-out), not to
        # the clock: a page left open for hours can still save.
        WTF_CSRF_TIME_LIMIT=None,
        # "Keep me signed in": two weeks, not Flask-Login's year; the cookie
        # names the user's session token, so signing out ends it too.
        REMEMBER_COOKIE_DURATION=timedelta(days=14),
        REMEMBER_COOKIE_HTTPONLY=True,
        REMEMBER_COOKIE_SAMESITE="Lax",
        FRAMES_PER_PAGE=120,
        # Object classes: the label field completes from the project's list
        # (flask egonet classes); True refuses a label outside it (docs/labelling.md).
        LABEL_CLASSES_STRICT=False,
        # What one request may cost: imported frames (and so GrabCut's) are at
        # most MAX_FRAME_SIDE pixels a side; a stroke has at most so many
        # points and so wide a brush (the labelling page's largest are 4000
        # and 200), and one object's strokes may sweep at most so many pixels
        # (labelling.stroke_pixels). GrabCut sessions and frames kept in a
        # worker's memory, and decoded frames shared on disk, are counted in bytes.
        MAX_FRAME_SIDE=4096,
        GRABCUT_MAX_STROKE_POINTS=4000,
        GRABCUT_MAX_RADIUS=256,
        GRABCUT_MAX_STROKE_PIXELS=250_000_000,
        GRABCUT_CACHE_BYTES=128 * 1024**2,
        GRABCUT_IMAGE_CACHE_BYTES=192 * 1024**2,
        GRABCUT_DISK_CACHE_BYTES=1024**3,
        # numpy's BLAS and OpenCV's threads per process (None: the libraries'
        # defaults, one per core). A request's GrabCut and scores run on one
        # core: gunicorn's workers x threads already share the cores, and
        # library threads that wait for a busy core spin (a GrabCut stroke
        # costs 2-4x the CPU so).
        COMPUTE_THREADS=1,
        PRODUCTION=False,
        # How many reverse proxies stand in front (0: none). Behind one, every
        # request comes from the proxy's address: with TRUSTED_PROXIES=n the
        # client's address and scheme are read from the n-th last entry of
        # X-Forwarded-For / X-Forwarded-Proto (Werkzeug's ProxyFix), which the
        # proxies append. Set it only to the number there really are: with more,
        # a client could name any address it likes (docs/deployment.md).
        TRUSTED_PROXIES=0,
    )


def _configure(app: Flask, test_config: dict | None) -> None:
    """Defaults, then ``instance/config.py`` and ``FLASK_*`` variables (or the
    test mapping instead); then the database URL's driver and the secret key,
    and in production the key's length check and HTTPS-only cookies."""
    from app import security

    instance = Path(app.instance_path)
    app.config.from_mapping(_default_config(instance))
    if test_config is None:
        app.config.from_pyfile("config.py", silent=True)
        app.config.from_prefixed_env()
    else:
        app.config.from_mapping(test_config)
    for gone, area in (("MEDIA_ROOT", "media"), ("CHECKPOINT_ROOT", "checkpoints"), ("EXPORT_ROOT", "exports")):
        if gone in app.config:
            raise RuntimeError(f"{gone} is replaced by STORAGE_URL, the folder (or s3://bucket/prefix) that holds {area}/: "
                               f"set STORAGE_URL to {gone}'s parent folder (docs/deployment.md)")
    app.config["SQLALCHEMY_DATABASE_URI"] = normalise_database_url(app.config["SQLALCHEMY_DATABASE_URI"])
    os.makedirs(app.instance_path, exist_ok=True)
    if not app.config.get("SECRET_KEY"):
        app.config["SECRET_KEY"] = instance_secret_key(instance)
    security.require_production_safety(app)
    proxies = app.config["TRUSTED_PROXIES"]
    if type(proxies) is not int or not 0 <= proxies <= 10:
        raise RuntimeError(f"TRUSTED_PROXIES must be a whole number from 0 to 10 (the proxies in front), not {proxies!r}")
    if proxies:
        app.wsgi_app = ProxyFix(app.wsgi_app, x_for=proxies, x_proto=proxies)
    if app.config["COMPUTE_THREADS"] is not None:
        threadpoolctl.threadpool_limits(limits=int(app.config["COMPUTE_THREADS"]), user_api="blas")
        cv2.setNumThreads(int(app.config["COMPUTE_THREADS"]))


def _init_extensions(app: Flask) -> None:
    """Bind the database, migrations, CSRF and log-in to the app."""
    from app.extensions import csrf, db, login_manager, migrate

    db.init_app(app)
    migrate.init_app(app, db, directory=str(Path(app.root_path).parent / "migrations"), render_as_batch=True)
    csrf.init_app(app)
    login_manager.init_app(app)
    login_manager.login_view = "auth.login"

    @login_manager.user_loader
    def load_user(user_id: str):
        # "<id>:<session token>" (User.get_id): only the current token signs in.
        from app.services.users import user_for_session

        return user_for_session(user_id)


def _register(app: Flask) -> None:
    """The throttle, the queue, the error handlers, the access checks and
    security headers, the blueprints, the navigation and the ``flask egonet`` CLI."""
    from app import errors, queue, security, throttle
    from app.blueprints import (
        api,
        auth,
        exports,
        frames,
        label,
        navigation,
        participate,
        scores,
        studies,
        training,
        users,
    )
    from app.cli import bp as cli_bp

    throttle.init_app(app)
    queue.init_app(app)
    errors.register(app)
    security.register(app)
    app.register_blueprint(auth.bp)
    for module in (frames, api, label, exports, studies, participate, training, scores, users):
        app.register_blueprint(module.bp)
    app.context_processor(navigation)
    app.register_blueprint(cli_bp)
