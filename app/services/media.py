"""Content-addressed media storage under the instance folder.

A file is stored under ``<root>/<h[:2]>/<h><suffix>`` where ``h`` is the
SHA-256 of its bytes, written to a temporary file in the same folder and
renamed into place, so a reader never sees half a file and writing the same
bytes twice is a no-op. The database stores the relative path.
"""

import hashlib
import os
import tempfile
from pathlib import Path

from flask import current_app


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
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=suffix)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    if written is not None:
        written.append(path)
    return rel


def read(relative: str) -> bytes:
    return absolute_path(relative).read_bytes()
