"""Where the site's durable files live: a local folder or an S3-compatible bucket.

``STORAGE_URL`` (``FLASK_STORAGE_URL``) is a folder (the default: the
instance folder) or ``s3://bucket/prefix``. The bucket's endpoint and
credentials come from the standard AWS variables (``AWS_ENDPOINT_URL``,
``AWS_ACCESS_KEY_ID``, ``AWS_SECRET_ACCESS_KEY``, ``AWS_DEFAULT_REGION``),
never from the database or a page.

Files are named by keys, posix paths under one area each: ``media/`` (frames,
depth, DHG, masks: content-addressed, so never changed once written),
``checkpoints/`` (training runs and uploaded weights) and ``exports/``
(export zips). In a folder a key is a path under it, so an instance folder
from before this module is read as it is. This module and
``app.services.media`` on top of it are the only code that touches the
site's files; a path under the folder is never built elsewhere.

Code that needs a file on disk (OpenCV, torch, ``send_file``) asks for
``local_path(key)``: the file itself in a folder; for a bucket a copy in this
host's cache (``CACHE_ROOT/storage``, at most ``STORAGE_CACHE_BYTES``, the
least recently used dropped first). A media key's copy is good for ever;
another key's copy is checked against the bucket's ETag on each call.

A bucket that cannot be reached raises ``StorageUnavailable`` (the app
answers 503 and tries again on the next request); a missing key raises
``FileNotFoundError`` on both backends.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Protocol

from flask import current_app

from app.errors import StorageUnavailable
from egonet.io import write_atomic

Data = bytes | Callable[[BinaryIO], None]


class StorageProblem(RuntimeError):
    """A storage operation that cannot go ahead (a bad URL, a copy that does not match); one line says why."""


@dataclass(frozen=True)
class Entry:
    key: str
    size: int
    modified: float  # seconds since the epoch


class Store(Protocol):
    url: str

    def put(self, key: str, data: Data) -> None: ...
    def put_file(self, key: str, path: Path) -> None: ...
    def get(self, key: str) -> bytes: ...
    def local_path(self, key: str) -> Path: ...
    def exists(self, key: str) -> bool: ...
    def delete(self, key: str) -> None: ...
    def delete_prefix(self, prefix: str) -> None: ...
    def list(self, prefix: str) -> Iterator[Entry]: ...


def _check_key(key: str) -> str:
    parts = key.split("/")
    if not key or key.startswith("/") or any(p in ("", ".", "..") for p in parts):
        raise ValueError(f"not a storage key: {key!r}")
    return key


class LocalStore:
    """Keys are files under ``root``; writes are atomic and flushed to disk."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.url = str(self.root)

    def _path(self, key: str) -> Path:
        return self.root / _check_key(key)

    def put(self, key: str, data: Data) -> None:
        write_atomic(self._path(key), data, durable=True)

    def put_file(self, key: str, path: Path) -> None:
        with open(path, "rb") as src:
            write_atomic(self._path(key), lambda dst: shutil.copyfileobj(src, dst, 1 << 20), durable=True)

    def get(self, key: str) -> bytes:
        return self._path(key).read_bytes()

    def local_path(self, key: str) -> Path:
        path = self._path(key)
        if not path.is_file():
            raise FileNotFoundError(f"storage has no {key}")
        return path

    def exists(self, key: str) -> bool:
        return self._path(key).is_file()

    def delete(self, key: str) -> None:
        self._path(key).unlink(missing_ok=True)

    def delete_prefix(self, prefix: str) -> None:
        shutil.rmtree(self._path(prefix.rstrip("/")), ignore_errors=True)

    def list(self, prefix: str) -> Iterator[Entry]:
        top = self._path(prefix.rstrip("/"))
        if not top.is_dir():
            return
        for dirpath, _, names in os.walk(top):
            for name in names:
                if name.startswith(".tmp-"):  # a write in flight
                    continue
                path = Path(dirpath) / name
                with contextlib.suppress(FileNotFoundError):
                    stat = path.stat()
                    yield Entry(path.relative_to(self.root).as_posix(), stat.st_size, stat.st_mtime)


class S3Store:
    """Keys are objects under ``s3://bucket/prefix``; reads that need a file go through a local cache."""

    def __init__(self, url: str, cache: Path, cache_bytes: int):
        import boto3
        from botocore.config import Config

        bucket, _, prefix = url.removeprefix("s3://").partition("/")
        if not bucket:
            raise ValueError(f"STORAGE_URL {url!r} names no bucket: use s3://bucket/prefix")
        self.url, self.bucket, self.prefix = url, bucket, prefix.strip("/")
        self.cache = cache
        self.copies = HostCache(cache, cache_bytes)
        # Fail within seconds when the store is down: a page answers 503, not a hung worker.
        config = Config(connect_timeout=3, read_timeout=30, retries={"max_attempts": 2, "mode": "standard"})
        self.client = boto3.client("s3", config=config)

    def _key(self, key: str) -> str:
        key = _check_key(key)
        return f"{self.prefix}/{key}" if self.prefix else key

    @contextlib.contextmanager
    def _reachable(self, key: str = "") -> Iterator[None]:
        from botocore.exceptions import BotoCoreError, ClientError

        try:
            yield
        except ClientError as exc:
            error = exc.response.get("Error", {})
            status = exc.response.get("ResponseMetadata", {}).get("HTTPStatusCode", 0)
            if error.get("Code") in ("404", "NoSuchKey", "NotFound"):
                raise FileNotFoundError(f"storage has no {key}") from exc
            # A 5xx, or a bucket that is missing or refuses these keys: the store is not usable as configured.
            raise StorageUnavailable(f"storage {self.url} answered {status} {error.get('Code', '')}".rstrip()) from exc
        except BotoCoreError as exc:  # connection refused, time-outs, closed connections
            raise StorageUnavailable(f"storage {self.url} is unreachable ({type(exc).__name__})") from exc

    def put(self, key: str, data: Data) -> None:
        if callable(data):
            with tempfile.TemporaryFile() as spool:
                data(spool)
                spool.seek(0)
                with self._reachable(key):
                    self.client.upload_fileobj(spool, self.bucket, self._key(key))
            return
        with self._reachable(key):
            self.client.put_object(Bucket=self.bucket, Key=self._key(key), Body=data)

    def put_file(self, key: str, path: Path) -> None:
        with self._reachable(key):
            self.client.upload_file(str(path), self.bucket, self._key(key))

    def get(self, key: str) -> bytes:
        with self._reachable(key):
            return self.client.get_object(Bucket=self.bucket, Key=self._key(key))["Body"].read()

    def local_path(self, key: str) -> Path:
        """A copy on this host: kept for ever for media, checked against the ETag otherwise."""
        if key.startswith("media/"):
            path = self.cache / key
            tag = None
        else:
            with self._reachable(key):
                tag = self.client.head_object(Bucket=self.bucket, Key=self._key(key))["ETag"].strip('"')
            path = self.cache / f"{key}@{tag}"
        if self.copies.hit(path):
            return path
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-")
        os.close(fd)
        try:
            with self._reachable(key):
                self.client.download_file(self.bucket, self._key(key), tmp)
            os.replace(tmp, path)
        finally:
            Path(tmp).unlink(missing_ok=True)
        self.copies.added(path)
        return path

    def exists(self, key: str) -> bool:
        try:
            with self._reachable(key):
                self.client.head_object(Bucket=self.bucket, Key=self._key(key))
        except FileNotFoundError:
            return False
        return True

    def delete(self, key: str) -> None:
        with self._reachable(key):
            self.client.delete_object(Bucket=self.bucket, Key=self._key(key))

    def delete_prefix(self, prefix: str) -> None:
        keys = [entry.key for entry in self.list(prefix)]
        for start in range(0, len(keys), 1000):
            chunk = [{"Key": self._key(k)} for k in keys[start:start + 1000]]
            with self._reachable(prefix):
                self.client.delete_objects(Bucket=self.bucket, Delete={"Objects": chunk, "Quiet": True})

    def list(self, prefix: str) -> Iterator[Entry]:
        base = f"{self.prefix}/" if self.prefix else ""
        pages = self.client.get_paginator("list_objects_v2").paginate(Bucket=self.bucket, Prefix=base + prefix.strip("/") + "/")
        with self._reachable(prefix):
            for page in pages:
                for item in page.get("Contents", []):
                    yield Entry(item["Key"][len(base):], item["Size"], item["LastModified"].timestamp())


class HostCache:
    """A folder of this host's own files (a bucket's copies, thumbnails, figures): at most ``budget`` bytes,
    the least recently used dropped first.

    Walking a large folder costs far more than a download, so it is walked only when this process's count
    says it may be over budget, and then trimmed to 90 %: once per tenth of the budget added, not per file.
    """

    def __init__(self, folder: Path, budget: int):
        self.folder, self.budget = Path(folder), int(budget)
        self._bytes: int | None = None  # as this process counts them

    def hit(self, path: Path) -> bool:
        """Whether ``path`` is there (and mark it most recently used)."""
        try:
            os.utime(path)
        except FileNotFoundError:
            return False
        return True

    def added(self, path: Path) -> None:
        size = path.stat().st_size
        if self._bytes is None or self._bytes + size > self.budget:
            self._bytes = _trim(self.folder, self.budget * 9 // 10, keep=path)
        else:
            self._bytes += size


def _trim(folder: Path, budget: int, *, keep: Path) -> int:
    """Delete the least recently used copies under ``folder`` until they fit in ``budget`` bytes; the bytes left."""
    files = []
    for dirpath, _, names in os.walk(folder):
        for name in names:
            with contextlib.suppress(OSError):
                path = Path(dirpath) / name
                stat = path.stat()
                files.append((stat.st_mtime, stat.st_size, path))
    total = sum(size for _, size, _ in files)
    for _, size, path in sorted(files):
        if total <= budget:
            break
        if path != keep:
            with contextlib.suppress(OSError):
                path.unlink()
            total -= size
    return total


def open_store(url: str, *, cache: Path, cache_bytes: int) -> Store:
    """The store a ``STORAGE_URL`` names: ``s3://bucket/prefix`` or a folder."""
    if url.startswith("s3://"):
        return S3Store(url, cache, cache_bytes)
    if "://" in url and not url.startswith("file://"):
        raise ValueError(f"STORAGE_URL {url!r}: use a folder or s3://bucket/prefix")
    return LocalStore(url.removeprefix("file://"))


def open_url(url: str) -> Store:
    """A folder or bucket with this app's cache settings (an import's source, a migration's target)."""
    config = current_app.config
    return open_store(str(url), cache=Path(config["CACHE_ROOT"]) / "storage", cache_bytes=config["STORAGE_CACHE_BYTES"])


def open_parent(url: str) -> tuple[Store, str]:
    """``s3://bucket/prefix/name`` as the store ``s3://bucket/prefix`` and the key ``name`` in it (a folder
    or an object: an import's source, an export's folder)."""
    parent, _, name = url.rstrip("/").rpartition("/")
    if not name or parent in ("s3:", "s3:/"):
        raise StorageProblem(f"{url}: name a folder in the bucket (s3://bucket/prefix/name)")
    return open_url(parent), name


def store() -> Store:
    """This app's store, made on first use."""
    extensions = current_app.extensions
    if "egonet.storage" not in extensions:
        extensions["egonet.storage"] = open_url(current_app.config["STORAGE_URL"])
    return extensions["egonet.storage"]


def each(work: Callable[[Entry], str], entries: list[Entry], on_progress: Callable[[int], None] | None = None) -> list[str]:
    """``work(entry)`` for every entry, eight at a time (a bucket's latency, not its bandwidth, is the limit);
    the results in order. The first failure stops the rest."""
    pool = ThreadPoolExecutor(8)
    try:
        results = []
        for result in pool.map(work, entries):
            results.append(result)
            if on_progress is not None:
                on_progress(1)
        return results
    finally:
        pool.shutdown(cancel_futures=True)


# Moving the site's files to another store (flask egonet storage-migrate)

AREAS = ("media", "checkpoints", "exports")


@dataclass
class MigrateReport:
    files: int = 0
    bytes: int = 0
    copied: int = 0
    present: int = 0  # there already, equal
    bad: list[str] = field(default_factory=list)  # check_only: missing or different there


def migrate(target: Store, *, check_only: bool = False, on_start: Callable[[int], None] | None = None,
            on_progress: Callable[[int], None] | None = None) -> MigrateReport:
    """Copy every file of this app's store (``AREAS``) to ``target`` and check each copy.

    A file is equal to its copy when their sizes match and, for media, the
    copy has the SHA-256 its name holds. Equal copies are kept, so running
    it again after a failure copies only the rest; each new copy is checked
    so. ``check_only`` copies nothing and lists the files whose copy is
    missing or different in ``report.bad``.

    Raises:
        StorageProblem: a copy that does not match (it is deleted), or ``target`` is this store.
        StorageUnavailable: either store cannot be reached.
    """
    source = store()
    if _same(source.url, target.url):
        raise StorageProblem(f"{target.url} is the current STORAGE_URL: give another folder or bucket")
    entries = [entry for area in AREAS for entry in source.list(area)]
    there = {entry.key: entry.size for area in AREAS for entry in target.list(area)}
    if on_start is not None:
        on_start(len(entries))

    def one(entry: Entry) -> str:
        if there.get(entry.key) == entry.size and _intact(target, entry.key):
            return "present"
        if check_only:
            return "bad"
        target.put_file(entry.key, source.local_path(entry.key))
        if not _intact(target, entry.key, entry.size):
            target.delete(entry.key)
            raise StorageProblem(f"{entry.key}: the copy in {target.url} does not match the original")
        return "copied"

    results = each(one, entries, on_progress)
    return MigrateReport(files=len(entries), bytes=sum(e.size for e in entries), copied=results.count("copied"),
                         present=results.count("present"),
                         bad=sorted(e.key for e, result in zip(entries, results, strict=True) if result == "bad"))


def _intact(target: Store, key: str, size: int | None = None) -> bool:
    """Whether ``target``'s copy of ``key`` has ``size`` bytes (when given) and, for media, the hash its name holds."""
    if key.startswith("media/"):
        data = target.get(key)
        return (size is None or len(data) == size) and hashlib.sha256(data).hexdigest() == Path(key).stem
    folder = key.rpartition("/")[0]
    return size is None or next((e.size for e in target.list(folder) if e.key == key), None) == size


def _same(a: str, b: str) -> bool:
    if a.startswith("s3://") or b.startswith("s3://"):
        return a.rstrip("/") == b.rstrip("/")
    return Path(a).resolve() == Path(b).resolve()
