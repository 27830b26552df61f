"""Checkpoints in the site's storage (``app.services.storage``), and the scratch folder a run trains in.

Keys, all under ``checkpoints/``:

* ``run-<id>/<fold>.pt``, ``run-<id>/depth.pt``, ``run-<id>/released.pt``: a run's checkpoints;
* ``run-<id>/config.json``: the engine's resolved configuration;
* ``uploads/<token>/meta.json`` and ``uploads/<token>/part-<offset>``: a released model being uploaded.

A ``Checkpoint`` row's ``path`` is the key after ``checkpoints/``, so an
instance folder from before storage keys reads as it is. Training writes
into a folder of this host's (``CACHE_ROOT/training/run-<id>``) and each file
goes to storage as soon as it is written (:class:`Uploader`); a run that
goes on, on this host or another, first takes its files back from storage
(:func:`fetch_run`), so it continues from the last epoch storage has.
"""

import hashlib
import shutil
from pathlib import Path

from flask import current_app

from app.services.storage import store as storage
from egonet.errors import EgonetError

AREA = "checkpoints/"


def run_folder(run_id: int) -> str:
    """A run's files: the key after ``checkpoints/`` of its folder."""
    return f"run-{run_id}"


def load(path: str) -> dict:
    """The checkpoint at ``checkpoints/<path>`` (a ``Checkpoint.path``), through this host's cached copy.

    Raises:
        EgonetError: The file is missing or is no EgoNet checkpoint.
    """
    from egonet.checkpoint import load_checkpoint

    try:
        local = storage().local_path(AREA + path)
    except FileNotFoundError:
        raise EgonetError(f"checkpoint file {path} is missing from storage", field="checkpoint") from None
    return load_checkpoint(local)


def save(path: str, state) -> None:
    """Write a checkpoint to ``checkpoints/<path>`` (atomically: a reader sees the old file or the new)."""
    import torch

    storage().put(AREA + path, lambda fh: torch.save(dict(state), fh))


def local_path(path: str) -> Path:
    """The file on this host (a bucket's: a copy in this host's cache, checked against the bucket)."""
    return storage().local_path(AREA + path)


def exists(path: str) -> bool:
    return storage().exists(AREA + path)


def read(path: str) -> bytes:
    return storage().get(AREA + path)


def put(path: str, data) -> None:
    storage().put(AREA + path, data)


def delete(path: str) -> None:
    storage().delete(AREA + path)


def delete_folder(folder: str) -> None:
    storage().delete_prefix(AREA + folder)


def listing(folder: str) -> list:
    """``(path, size, modified)`` of every file under ``checkpoints/<folder>/``."""
    return [(entry.key.removeprefix(AREA), entry.size, entry.modified) for entry in storage().list(AREA + folder)]


def scratch(run_id: int, rank: int = 0) -> Path:
    """The folder this host (and torch process) trains run ``run_id`` in."""
    return Path(current_app.config["CACHE_ROOT"]) / "training" / (run_folder(run_id) + (f"-rank{rank}" if rank else ""))


class Uploader:
    """Puts each file of a run's scratch folder into storage once it is new or has changed.

    A file's content digest says whether it changed: two saves within one
    tick of a coarse file-system clock can leave the same size and time.
    """

    def __init__(self, run_id: int, folder: Path):
        self.prefix, self.folder = run_folder(run_id), folder
        self.sent: dict[str, str] = {}

    def __call__(self) -> None:
        for path in sorted(self.folder.glob("*")):
            if path.name.startswith(".tmp-") or not path.is_file():
                continue  # a write in flight
            if self.sent.get(path.name) != (digest := _digest(path)):
                storage().put_file(f"{AREA}{self.prefix}/{path.name}", path)
                self.sent[path.name] = digest


def _digest(path: Path) -> str:
    with path.open("rb") as fh:
        return hashlib.file_digest(fh, "blake2b").hexdigest()


def fetch_run(run_id: int, folder: Path) -> Uploader:
    """Fill ``folder`` with the run's files as storage has them (nothing else) and return its uploader."""
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    uploader = Uploader(run_id, folder)
    for path, _, _ in listing(run_folder(run_id)):
        name = path.removeprefix(run_folder(run_id) + "/")
        if "/" in name:
            continue
        shutil.copyfile(local_path(path), folder / name)
        uploader.sent[name] = _digest(folder / name)
    return uploader
