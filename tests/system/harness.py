"""The real production server on PostgreSQL, and clients that act like the pages.

Used by the crash test and by bench/load.py. The server is gunicorn running
``app:create_app()`` (the production entry point of docs/deployment.md) in its own
process group, so a test can kill -9 all of it at once.
"""

import os
import re
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path

import httpx
import numpy as np
import sqlalchemy as sa
from pycocotools import mask as coco_mask

from app import create_app, normalise_database_url

ROOT = Path(__file__).resolve().parents[2]
SECRET = "system-test-secret-key-0123456789abcdef"


def private_schema_url(base_url: str) -> tuple[str, str]:
    """Create an empty schema; return (url with search_path set, schema name)."""
    schema = f"sys_{uuid.uuid4().hex[:12]}"
    base = normalise_database_url(base_url)
    engine = sa.create_engine(base)
    with engine.begin() as conn:
        conn.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
    engine.dispose()
    sep = "&" if "?" in base else "?"
    return f"{base}{sep}options=-csearch_path%3D{schema}", schema


def drop_schema(base_url: str, schema: str) -> None:
    engine = sa.create_engine(normalise_database_url(base_url))
    with engine.begin() as conn:
        conn.execute(sa.text(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE'))
    engine.dispose()


def app_config(database_url: str, instance: Path) -> dict:
    return {
        "SQLALCHEMY_DATABASE_URI": database_url,
        "STORAGE_URL": str(instance),
        "CACHE_ROOT": str(instance / "cache"),
        "SECRET_KEY": SECRET,
    }


def make_app(database_url: str, instance: Path):
    return create_app(app_config(database_url, instance))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """gunicorn serving the app (``settings``: more ``FLASK_*`` variables); ``kill()`` is kill -9 of the whole process group."""

    def __init__(self, database_url: str, instance: Path, *, workers: int = 2, threads: int = 4, port: int | None = None,
                 settings: dict[str, str] | None = None):
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = dict(os.environ)
        env.update({f"FLASK_{k}": v for k, v in app_config(database_url, instance).items()})
        env["FLASK_PRODUCTION"] = "false"  # plain HTTP on loopback: no Secure cookies
        env.update({f"FLASK_{k}": v for k, v in (settings or {}).items()})
        self.log = open(instance / f"gunicorn-{self.port}.log", "ab")
        self.process = subprocess.Popen(
            [sys.executable, "-m", "gunicorn", "--workers", str(workers), "--threads", str(threads),
             "--bind", f"127.0.0.1:{self.port}", "--timeout", "60", "--keep-alive", "30", "app:create_app()"],
            cwd=ROOT, env=env, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True,
        )
        self.wait_ready()

    def wait_ready(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"gunicorn exited with {self.process.returncode}; see {self.log.name}")
            try:
                if httpx.get(self.url + "/login", timeout=2).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise TimeoutError("gunicorn did not start")

    def kill(self) -> None:
        os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait(timeout=10)
        self.log.close()

    def stop(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            self.process.wait(timeout=30)
        self.log.close()


def rle(mask: np.ndarray) -> dict:
    """A bool mask as the labelling API's RLE (COCO's compressed counts)."""
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in encoded["size"]], "counts": encoded["counts"].decode()}


def csrf_token(client: httpx.Client, path: str = "/login") -> str:
    page = client.get(path)
    return re.search(r'name="csrf-token" content="([^"]+)"', page.text).group(1)


def staff_client(base_url: str, username: str, password: str, **options) -> httpx.Client:
    client = httpx.Client(base_url=base_url, **options)
    token = csrf_token(client)
    response = client.post("/login", data={"username": username, "password": password, "csrf_token": token})
    if response.status_code != 302:
        client.close()
        raise RuntimeError(f"log-in of {username} failed: {response.status_code}")
    client.headers["X-CSRFToken"] = csrf_token(client, "/")
    client.headers["Accept"] = "application/json"
    return client


def participant_client(base_url: str, code: str, **options) -> httpx.Client:
    """Enter a study by code, agree to the consent and start the session."""
    client = httpx.Client(base_url=base_url, **options)
    token = csrf_token(client, "/s/")
    client.post("/s/", data={"code": code, "csrf_token": token})
    token = csrf_token(client, "/s/consent")
    client.post("/s/consent", data={"decision": "agree", "csrf_token": token})
    client.post("/s/start", data={"csrf_token": token})
    client.headers["X-CSRFToken"] = token
    client.headers["Accept"] = "application/json"
    return client
