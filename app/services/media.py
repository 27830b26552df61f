"""Content-addressed media in the site's storage (``app.services.storage``).

A file is stored under the key ``media/<h[:2]>/<h><suffix>`` where ``h`` is
the SHA-256 of its bytes, written atomically (a reader never sees half a
file) and never changed again, so writing the same bytes twice is a no-op
and a host's cached copy never goes stale. The database stores the path
after ``media/``.
"""

import contextlib
import hashlib
import re
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from flask import current_app

from app.services.storage import HostCache, StorageUnavailable
from app.services.storage import store as storage
from egonet.io import write_atomic  # the one atomic writer: media, caches and checkpoints

AREA = "media/"
NAME = re.compile(r"[0-9a-f]{2}/[0-9a-f]{64}\.[a-z0-9]{1,8}")  # what relative_path makes


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def relative_path(digest: str, suffix: str) -> str:
    return f"{digest[:2]}/{digest}{suffix}"


def derived(name: str, make: Callable[[], bytes]) -> Path:
    """A file made from the site's files (a thumbnail, an overlay, a figure), kept on this host.

    Made atomically on first use under ``CACHE_ROOT/derived``; the folder holds at most
    ``DERIVED_CACHE_BYTES``, the least recently used dropped first. ``name`` must hold the content
    hashes of what it is made from, so a kept file never goes stale.
    """
    cache = _derived()
    path = cache.folder / name
    if not cache.hit(path):
        write_atomic(path, make())
        cache.added(path)
    return path


def derived_path(name: str) -> Path:
    """Where ``derived(name, ...)`` keeps its file (which may not be made yet)."""
    return _derived().folder / name


def _derived() -> HostCache:
    extensions = current_app.extensions
    if "egonet.derived" not in extensions:
        folder = Path(current_app.config["CACHE_ROOT"]) / "derived"
        extensions["egonet.derived"] = HostCache(folder, current_app.config["DERIVED_CACHE_BYTES"])
    return extensions["egonet.derived"]


def local_path(relative: str) -> Path:
    """The file on this host's disk (in a bucket's case, this host's cached copy)."""
    return storage().local_path(AREA + relative)


def store(data: bytes, suffix: str, *, written: list[str] | None = None) -> str:
    """Store bytes atomically; return their relative path.

    Args:
        data: the encoded file.
        suffix: the file ending, with its dot (".png").
        written: if given, the relative path is appended when this call
            created the file, so a failed import can remove what it added.
    """
    rel = relative_path(sha256(data), suffix)
    if storage().exists(AREA + rel):
        return rel
    storage().put(AREA + rel, data)
    if written is not None:
        written.append(rel)
    return rel


@contextlib.contextmanager
def transaction() -> Iterator[list[str]]:
    """One database transaction with the media it writes.

    Yields the list that ``store(..., written=...)`` appends new files to.
    Commits at the end; on any failure rolls back and removes the media this
    block created, so nothing is half-kept.
    """
    from app.extensions import db

    written: list[str] = []
    try:
        yield written
        db.session.commit()
    except BaseException:
        db.session.rollback()
        for rel in written:
            with contextlib.suppress(OSError, StorageUnavailable):  # media-check --remove-orphans finds the rest
                storage().delete(AREA + rel)
        raise


def read(relative: str) -> bytes:
    return storage().get(AREA + relative)


@dataclass
class MediaReport:
    referenced: int = 0
    files: int = 0
    missing: list[str] = field(default_factory=list)
    orphans: list[str] = field(default_factory=list)
    removed: list[str] = field(default_factory=list)


def referenced_paths() -> set[str]:
    """Every media path the database refers to (columns marked ``info={"media": True}``)."""
    from app.extensions import db

    paths: set[str] = set()
    for table in db.metadata.sorted_tables:
        for column in table.columns:
            if column.info.get("media"):
                paths.update(p for p in db.session.execute(db.select(column).where(column.is_not(None))).scalars())
    return paths


def check(*, remove_orphans: bool = False, grace_s: float = 3600.0) -> MediaReport:
    """Compare the media in storage with the database.

    Media are written before the transaction that refers to them commits, so
    a crash in between leaves an unreferenced file (an orphan); it is never
    a lost acknowledged write. Orphans older than ``grace_s`` (so not part of
    a transaction still in flight) are removed when asked. A referenced file
    that is missing is reported: that would be real damage.
    """
    referenced = referenced_paths()
    report = MediaReport(referenced=len(referenced))
    present: set[str] = set()
    now = time.time()
    for entry in storage().list(AREA):
        rel = entry.key.removeprefix(AREA)
        report.files += 1
        present.add(rel)
        if rel in referenced:
            continue
        report.orphans.append(rel)
        if remove_orphans and now - entry.modified > grace_s:
            storage().delete(entry.key)
            report.removed.append(rel)
    report.missing = sorted(referenced - present)
    return report
