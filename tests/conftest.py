"""Test-suite options shared by every folder.

Slow and browser tests carry markers and are skipped unless ``--all`` is
given (the README's test command and ``.ci/run`` give it). ``--all`` also
spreads the tests over the machine's cores with pytest-xdist, unless ``-n``
says otherwise (``-n 0`` runs them in one process). Tests go to the workers
in collection order and an idle worker takes over half of a busy one's
queue (``worksteal``): a worker keeps to one database backend for long runs
(pytest groups the tests by it), and no long file is left for one worker at
the end.
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


def pytest_addoption(parser):
    parser.addoption("--all", action="store_true", help="also run tests marked slow or browser")


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """``--all`` without ``-n``: pytest-xdist on every core (its workers get ``-n`` unset too)."""
    if config.getoption("--all") and getattr(config.option, "numprocesses", 0) is None and not hasattr(config, "workerinput"):
        config.option.numprocesses = "auto"
        if config.option.dist == "no":
            config.option.dist = "worksteal"


def pytest_collection_modifyitems(config, items):
    # Costly science whose outcome no database changes (fitting, training,
    # scoring arrays) runs once, on the default SQLite; the rest runs on both.
    # Likewise a bucket's tests (marked both_storages) run on SQLite only.
    twice = [item for item in items if _on_postgresql(item) and (item.get_closest_marker("one_database") or _on_s3(item))]
    if twice:
        config.hook.pytest_deselected(items=twice)
        items[:] = [item for item in items if item not in twice]
    if config.getoption("--all"):
        return
    skip = pytest.mark.skip(reason="marked slow or browser: run with --all")
    for item in items:
        if item.get_closest_marker("slow") or item.get_closest_marker("browser"):
            item.add_marker(skip)


def _on_postgresql(item) -> bool:
    callspec = getattr(item, "callspec", None)
    return callspec is not None and callspec.params.get("database_url") == "postgresql"


def _on_s3(item) -> bool:
    callspec = getattr(item, "callspec", None)
    return callspec is not None and callspec.params.get("storage_url") == "s3"


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
