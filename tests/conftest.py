"""Test-suite options shared by every folder.

Slow and browser tests carry markers and are skipped unless ``--all`` is
given (the README's test command and ``.ci/run`` give it). ``--all`` also
spreads the tests over the machine's cores (one worker more than cores) with pytest-xdist, unless ``-n``
says otherwise (``-n 0`` runs them in one process). Tests go to the workers
in collection order and an idle worker takes over half of a busy one's
queue (``worksteal``): a worker keeps to one database backend for long runs
(pytest groups the tests by it). The tests marked slow go first: the queues'
tails are then short tests, so no worker waits alone at the end for a long
one (training ran last, in tests/unit, and left one core idle for a minute).
"""

import functools
import os

import pytest
from hypothesis import settings

# No per-example time limit: on a shared 2-core machine one slow example is
# noise, not a failure (performance is measured in bench/, never in tests).
settings.register_profile("egonet", deadline=None)
settings.load_profile("egonet")

# Each test app's queue is the QUEUE_URL default, SQLite in its own instance
# folder: a queue set for this machine must not reach the tests (those that
# need Redis say so).
for name in ("EGONET_QUEUE_URL", "FLASK_QUEUE_URL"):
    os.environ.pop(name, None)

# A pytest-xdist worker is one of a core's worth of processes: torch, OpenMP, BLAS and OpenCV on one
# thread each, in the worker and in the servers and commands its tests start (set before any of them
# is imported). With the libraries' defaults (a thread per core) three workers on two cores ran six or
# more compute threads, whose waits for a busy core spin.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = "1"
    import cv2

    cv2.setNumThreads(1)


def pytest_addoption(parser):
    parser.addoption("--all", action="store_true", help="also run tests marked slow or browser")


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """``--all`` without ``-n``: pytest-xdist with a worker per core and one more (its workers get ``-n`` unset too).

    Many tests wait on a server, a browser, a subprocess or a lease, so a
    worker more than the cores keeps them busy: the whole ``--all`` run on a
    2-core machine took 755 s with 2 workers and 666 s with 3 (2026-12-04).
    """
    if config.getoption("--all") and getattr(config.option, "numprocesses", 0) is None and not hasattr(config, "workerinput"):
        config.option.numprocesses = (os.cpu_count() or 1) + 1
        if config.option.dist == "no":
            config.option.dist = "worksteal"


@pytest.hookimpl(trylast=True)  # after pytest has grouped the tests by database backend
def pytest_collection_modifyitems(config, items):
    # Costly science whose outcome no database changes (fitting, training,
    # scoring arrays) runs once, on the default SQLite; the rest runs on both.
    # Likewise a bucket's tests (marked both_storages) run on SQLite only, and
    # a slow one runs each backend and each storage once: SQLite with the
    # bucket, PostgreSQL with the folder (SQLite with the folder adds neither).
    twice = [item for item in items if _on_postgresql(item) and (item.get_closest_marker("one_database") or _on_s3(item))]
    if any(_on_postgresql(item) for item in items):
        twice += [item for item in items if item.get_closest_marker("slow") and _variant(item) == ("sqlite", "local")]
    if twice:
        config.hook.pytest_deselected(items=twice)
        items[:] = [item for item in items if item not in twice]
    if config.getoption("--all"):
        items.sort(key=lambda item: item.get_closest_marker("slow") is None)  # stable: each group keeps its order
        return
    skip = pytest.mark.skip(reason="marked slow or browser: run with --all")
    for item in items:
        if item.get_closest_marker("slow") or item.get_closest_marker("browser"):
            item.add_marker(skip)


def _variant(item) -> tuple[str | None, str | None]:
    """(database backend, storage) of a test parametrized over them, else None for each."""
    params = getattr(item, "callspec", None) and item.callspec.params or {}
    return params.get("database_url"), params.get("storage_url")


def _on_postgresql(item) -> bool:
    return _variant(item)[0] == "postgresql"


def _on_s3(item) -> bool:
    return _variant(item)[1] == "s3"


@pytest.fixture(scope="session", autouse=True)
def scrypt_once_per_password():
    """Werkzeug's scrypt costs about 0.25 s of CPU a hash and a check, and the
    tests create and sign in users by the hundred. Within a test session every
    new hash gets the same salt and each (password, salt) is derived once: the
    hashes stay real scrypt hashes, checked as in production, only not
    recomputed. (Servers the tests start in other processes hash as usual.)"""
    import werkzeug.security as security

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(security, "gen_salt", functools.cache(security.gen_salt))
        patch.setattr(security, "_hash_internal", functools.cache(security._hash_internal))
        yield


@pytest.fixture(scope="session", autouse=True)
def url_builders_compiled_once():
    """Werkzeug compiles two URL builders (generated Python) for every rule of
    every app: 45 of create_app's 56 ms, and the tests make an app per test.
    Within a test session a rule's builders are compiled once and shared by
    every app with the same rule: the same code Werkzeug generates, bound to
    each app's own rule. (Rules whose defaults fill a part of the URL keep
    their own: the converter writes that part into the code.)"""
    from werkzeug.routing.rules import Rule

    compile_builder, compiled = Rule._compile_builder, {}

    def once(rule, append_unknown=True):
        defaults = rule.defaults or {}
        if any(dynamic and name in defaults for dynamic, name in rule._trace):
            return compile_builder(rule, append_unknown)
        key = (rule.rule, tuple(rule._trace), tuple(defaults), append_unknown)
        if key not in compiled:
            compiled[key] = compile_builder(rule, append_unknown)
        return compiled[key]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Rule, "_compile_builder", once)
        yield


@pytest.fixture
def one_thread():
    """One torch thread: on a shared two-core machine, small models run several times faster so."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="session")
def full_rgb_caffemodel(tmp_path_factory):
    """A full-size file of the authors' RGB release (270 MB, zeros but fc9's bias), written once a session.

    Returns ``(path, fc9 bias)``. For slow tests only (tests/caffe_files.py writes it).
    """
    import numpy as np

    from tests.caffe_files import FULL, release_layers, write_caffemodel

    marker = np.arange(512, dtype=np.float32) / 512
    fc9 = [np.zeros((512, 4098, 1, 1), np.float32), marker]
    path = write_caffemodel(tmp_path_factory.mktemp("caffe") / "EgoNet_rgb.caffemodel",
                            release_layers(FULL["rgb"], {"fc9": fc9}))
    return path, marker


@pytest.fixture(scope="session")
def seaweedfs(tmp_path_factory):
    """A real S3-compatible store (SeaweedFS, tests/seaweed.py) for the session, with the bucket
    ``egonet-test``; the AWS variables the app reads point at it."""
    from tests.seaweed import SeaweedFS

    server = SeaweedFS(tmp_path_factory.mktemp("seaweedfs")).start()
    server.create_bucket("egonet-test")
    saved = {name: os.environ.get(name) for name in server.environ()}
    os.environ.update(server.environ())
    yield server
    server.stop()
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value
