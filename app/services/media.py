"""Content-addressed media storage under the instance folder.

A file is stored under ``<root>/<h[:2]>/<h><suffix>`` where ``h`` is the
SHA-256 of its bytes, written to a temporary file in the same folder and
renamed into place, so a reader never sees half a file and writing the same
bytes twice is a no-op. The database stores the relative path.
"""

import contextlib
import hashlib
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from flask import current_app

from egonet.io import write_atomic  # the one atomic writer: media, caches and checkpoints


def media_root() -> Path:
    return Path(current_app.config["MEDIA_ROOT"])


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def relative_path(digest: str, suffix: str) -> str:
    return f"{digest[:2]}/{digest}{suffix}"


def absolute_path(relative: str) -> Path:
    return media_root() / relative


def store(data: bytes, suffix: str, *, written: list[Path] | None = None) -> str:
    """Store bytes atomically; return their relative path.

    Args:
        data: the encoded file.
        suffix: the file ending, with its dot (".png").
        written: if given, the absolute path is appended when this call
            created the file, so a failed import can remove what it added.
    """
    rel = relative_path(sha256(data), suffix)
    path = media_root() / rel
    if path.exists():
        return rel
    write_atomic(path, data, durable=True)
    if written is not None:
        written.append(path)
    return rel


@contextlib.contextmanager
def transaction() -> Iterator[list[Path]]:
    """One database transaction with the media it writes.

    Yields the list that ``store(..., written=...)`` appends new files to.
    Commits at the end; on any failure rolls back and removes the media this
    block created, so nothing is half-kept.
    """
    from app.extensions import db

    written: list[Path] = []
    try:
        yield written
        db.session.commit()
    except BaseException:
        db.session.rollback()
        for path in written:
            path.unlink(missing_ok=True)
        raise


def read(relative: str) -> bytes:
    return absolute_path(relative).read_bytes()


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
    """Compare the media folder with the database.

    Media are written before the transaction that refers to them commits, so
    a crash in between leaves an unreferenced file (an orphan); it is never
    a lost acknowledged write. Orphans older than ``grace_s`` (so not part of
    a transaction still in flight) are removed when asked. A referenced file
    that is missing is reported: that would be real damage.
    """
    referenced = referenced_paths()
    root = media_root()
    report = MediaReport(referenced=len(referenced))
    present: set[str] = set()
    now = time.time()
    if root.exists():
        for path in root.rglob("*"):
            if not path.is_file():
                continue
            rel = path.relative_to(root).as_posix()
            report.files += 1
            present.add(rel)
            if rel in referenced:
                continue
            stale = now - path.stat().st_mtime > grace_s
            report.orphans.append(rel)
            if remove_orphans and stale:
                path.unlink(missing_ok=True)
                report.removed.append(rel)
    report.missing = sorted(referenced - present)
    return report
