"""Benchmark: the site's files in a local folder against an S3 bucket, in one run.

The bucket is SeaweedFS on loopback (``tests/seaweed.py``, started here);
the folder is a temporary one on this machine's disk. Each backend gets its
own SQLite database and the same input files, and the two are measured in
turns (local, then S3, for every repetition and request), so load from
elsewhere on a shared machine falls on both alike.

* **import**: ``app.services.importing.import_path`` (one transaction, as
  ``flask egonet import``) on folders of frames: the real first-person frames
  of ``shared/data/egonet-samples`` (RGB and DHG, 514x386 JPEG), the real
  RGB-D frames of ``shared/data/rgbd-primesense`` (640x480 JPEG and 16-bit
  depth PNG, intrinsics), each copied ``--copies`` times with a few pixels
  changed (so every file is new to the store), and demo-sized synthetic
  frames (``egonet.synth``, 320x240 RGB and depth PNG, intrinsics). Frames
  per second, the median of ``--repeats`` imports.
* **page**: ``GET /media/<rgb>`` (the frame page's image) and
  ``GET /frames/<id>/thumb.jpg`` through the test client, signed in, on the
  imported frames: the first request of each (the host has never seen the
  file: a bucket's copy is downloaded, the thumbnail made) and then
  ``--gets`` more (cached); p50 and p95.
* **GrabCut box**: a new host (a fresh app: empty instance folder and
  ``CACHE_ROOT``, same database and bucket, nothing in memory) boxes a frame
  it has never seen (first touch: the frame's RGB and depth are fetched from
  storage and decoded), then the same frame ``--again`` times more, each
  under another object key (cached). Each new host first serves a box on
  another frame, so its first request (making its S3 client, opening
  connections) is not timed, as a host that has been serving would not pay
  it (that first box is shown too). Then the same on new hosts
  whose cache already holds ``--cache-files`` files (20,000: what a 4 GiB
  ``STORAGE_CACHE_BYTES`` holds at ~200 kB a frame), as after a while of
  serving: keeping the cache within its bytes must not cost each download.
* **checkpoint**: ``torch.save`` of egonet-lite's ``state_dict`` (1.6 M
  parameters), then ``storage().put_file`` (save) and, on a new host,
  ``local_path`` plus ``torch.load`` (first load: downloaded into the cache)
  and the same again (cached: for a bucket the copy is checked against the
  object's ETag).

Goals (issue 37): cached GrabCut and page figures within 10 % of local;
first touch within 150 ms of local; import at least half of local throughput.

    .venv/bin/python bench/bench_storage.py [--repeats 5] [--copies 4] [--synthetic 24] [--hosts 8] [--gets 10]
        [--cache-files 20000]

Each line also says how many HTTP requests the S3 host sent to the bucket
(per frame for imports), counted on boto3's ``before-send`` event.
"""

from __future__ import annotations

import argparse
import os
import sys

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import json  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import torch  # noqa: E402
from flask_migrate import upgrade  # noqa: E402

from app import create_app  # noqa: E402
from app.extensions import db  # noqa: E402
from app.models import Activity, Frame, Sequence  # noqa: E402
from app.services.importing import import_path  # noqa: E402
from app.services.labelling import grabcut as grabcut_service  # noqa: E402
from app.services.storage import store  # noqa: E402
from app.services.users import create_user  # noqa: E402
from egonet import io  # noqa: E402
from egonet.network.builders import build_model  # noqa: E402
from egonet.synth import render_frame  # noqa: E402
from tests.app.conftest import CSRFClient  # noqa: E402
from tests.realdata import EGONET_SAMPLES as SAMPLES  # noqa: E402
from tests.realdata import PRIMESENSE  # noqa: E402
from tests.seaweed import SeaweedFS  # noqa: E402

PASSWORD = "bench-storage-password"
BUCKET = "bench"


# --------------------------------------------------------------------------
# Input folders (the same files for both backends)


def mark(image: np.ndarray, stamp: int) -> np.ndarray:
    """The image with an 8x8 block in its corner coloured by ``stamp``: a new file, the same picture."""
    out = image.copy()
    out[:8, :8] = (stamp % 251, (stamp // 251) % 251, 200)
    return out


def write_jpeg(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 92])


def write_bytes(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)


def intrinsics_json(K: np.ndarray, width: int, height: int) -> str:
    return json.dumps({"width": width, "height": height, "intrinsic_matrix": [float(v) for v in K.T.ravel()]})


def real_folders(out: Path, rep: int, copies: int) -> dict[str, Path]:
    """The real frames, each copied ``copies`` times with a stamp of its own."""
    folders = {}
    if SAMPLES.is_dir():
        folder = out / f"egonet-samples-{rep}"
        for path in sorted((SAMPLES / "rgb").glob("*.jpg")):
            rgb, dhg = io.read_image(path), io.read_image(SAMPLES / "dhg" / path.name)
            for k in range(copies):
                stamp = 1000 * rep + 10 * k + 1
                write_jpeg(folder / "rgb" / f"{path.stem}-{k}.jpg", mark(rgb, stamp))
                write_jpeg(folder / "dhg" / f"{path.stem}-{k}.jpg", mark(dhg, stamp))
        folders["egonet-samples"] = folder
    if PRIMESENSE.is_dir():
        folder = out / f"rgbd-primesense-{rep}"
        for path in sorted((PRIMESENSE / "color").glob("*.jpg")):
            rgb, depth = io.read_image(path), io.read_depth(PRIMESENSE / "depth" / f"{path.stem}.png")
            for k in range(copies):
                stamp = 1000 * rep + 10 * k + 2
                write_jpeg(folder / "color" / f"{path.stem}{k}.jpg", mark(rgb, stamp))
                depth_k = depth.copy()
                depth_k[:8, :8] = 0.5 + stamp / 1e4
                write_bytes(folder / "depth" / f"{path.stem}{k}.png", io.encode_depth_png(depth_k))
        (folder / "camera.json").write_text((PRIMESENSE / "camera_primesense.json").read_text())
        folders["rgbd-primesense"] = folder
    return folders


def synthetic_folder(out: Path, rep: int, count: int) -> Path:
    """Demo-sized frames (320x240 RGB and depth PNG, intrinsics), different for every ``rep``."""
    folder = out / f"synthetic-{rep}"
    for i in range(count):
        f = render_frame("dining", 1000 * rep + i)
        write_bytes(folder / "rgb" / f"{i:05d}.png", io.encode_png(f.rgb))
        write_bytes(folder / "depth" / f"{i:05d}.png", io.encode_depth_png(f.depth_m))
    (folder / "camera.json").write_text(intrinsics_json(f.K, f.rgb.shape[1], f.rgb.shape[0]))
    return folder


# --------------------------------------------------------------------------
# The two backends, each with hosts made on demand


class Backend:
    """A database and a store; ``host()`` is a new app server on them (own instance folder and cache)."""

    def __init__(self, name: str, storage_url: str, folder: Path):
        self.name, self.storage_url, self.folder = name, storage_url, folder
        self.database_url = f"sqlite:///{folder / 'egonet.sqlite3'}"
        self.hosts = 0
        self.main = self.host()
        with self.main.app_context():
            upgrade()
            create_user("bench", "admin", PASSWORD)
        self.client = self.signed_in(self.main)

    def host(self):
        self.hosts += 1
        instance = self.folder / f"host-{self.hosts}"
        app = create_app({"SQLALCHEMY_DATABASE_URI": self.database_url, "STORAGE_URL": self.storage_url,
                          "CACHE_ROOT": str(instance / "cache"), "SECRET_KEY": "bench-storage-" + "k" * 32,
                          "QUEUE_IN_PROCESS": False}, instance_path=str(instance))
        app.test_client_class = CSRFClient
        return app

    def signed_in(self, app) -> CSRFClient:
        client = app.test_client()
        if client.login("bench", PASSWORD).status_code != 302:
            raise RuntimeError(f"{self.name}: log-in failed")
        return client

    def frames(self, rep: int) -> list[tuple[int, str, int, int]]:
        """(id, rgb media path, width, height) of the frames of repetition ``rep``'s imports."""
        with self.main.app_context():
            query = (db.select(Frame.id, Frame.rgb_path, Frame.width, Frame.height).join(Sequence).join(Activity)
                     .where(Activity.name.endswith(f"-{rep}")).order_by(Activity.name, Frame.index))
            return [tuple(row) for row in db.session.execute(query)]


def turns(backends: list, n: int) -> list:
    """The backends in the order of turn ``n``: local first, then S3 first, and so on."""
    return backends if n % 2 == 0 else backends[::-1]


def ms_since(start: float) -> float:
    return 1e3 * (time.perf_counter() - start)


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def get(client: CSRFClient, url: str) -> float:
    start = time.perf_counter()
    response = client.get(url)
    size = len(response.get_data())
    ms = ms_since(start)
    response.close()
    if response.status_code != 200 or not size:
        raise RuntimeError(f"GET {url}: {response.status_code}")
    return ms


def box(client: CSRFClient, frame: tuple[int, str, int, int], key: str) -> float:
    frame_id, _, w, h = frame
    start = time.perf_counter()
    response = client.post("/api/label/grabcut/box", json={"frame_id": frame_id, "instance": key,
                                                           "box": [w // 4, h // 4, 3 * w // 4, 3 * h // 4]})
    ms = ms_since(start)
    if response.status_code != 200:
        raise RuntimeError(f"box on frame {frame_id}: {response.status_code} {response.get_data()[:200]!r}")
    return ms


def forget_memory() -> None:
    """Nothing of GrabCut's in this process's memory, as in a new server process."""
    grabcut_service._sessions = grabcut_service._Recent()
    grabcut_service._frames = grabcut_service._Recent()


# --------------------------------------------------------------------------
# The measures: each returns {measure: {"local": [values], "s3": [values], "requests": [the bucket's, per value]}}

Results = dict[str, dict[str, list[float]]]


def bucket_requests(app) -> Callable[[], int]:
    """How many HTTP requests this host's store has sent to the bucket so far (0 for a folder)."""
    sent = [0]
    with app.app_context():
        client = getattr(store(), "client", None)
    if client is not None:
        client.meta.events.register("before-send", lambda **_: sent.__setitem__(0, sent[0] + 1))
    return lambda: sent[0]


def add(results: Results, name: str, backend: Backend, value: float, requests: float) -> None:
    by = results.setdefault(name, {})
    by.setdefault(backend.name, []).append(value)
    if backend.name == "s3":
        by.setdefault("requests", []).append(requests)


def measure_import(backends: list[Backend], inputs: list[dict[str, Path]]) -> Results:
    """Frames per second by source, one value per repetition."""
    results: Results = {}
    sent = {b.name: bucket_requests(b.main) for b in backends}
    for rep, folders in enumerate(inputs):
        for k, (source, folder) in enumerate(folders.items()):
            for b in turns(backends, rep + k):
                with b.main.app_context():
                    before, start = sent[b.name](), time.perf_counter()
                    report = import_path(folder, activity=f"{source}-{rep}")
                    seconds = time.perf_counter() - start
                add(results, f"{source} ({report.added})", b, report.added / seconds,
                    (sent[b.name]() - before) / report.added)
    return results


def measure_pages(backends: list[Backend], gets: int) -> Results:
    results: Results = {}
    frames = {b.name: b.frames(0) for b in backends}
    sent = {b.name: bucket_requests(b.main) for b in backends}
    for n in range(gets + 1):
        for i in range(len(frames["local"])):
            for b in turns(backends, n + i):
                frame_id, rgb_path, *_ = frames[b.name][i]
                for kind, url in (("media", f"/media/{rgb_path}"), ("thumbnail", f"/frames/{frame_id}/thumb.jpg")):
                    before = sent[b.name]()
                    add(results, f"{kind} first" if n == 0 else kind, b, get(b.client, url), sent[b.name]() - before)
    return results


def measure_grabcut(backends: list[Backend], hosts: int, again: int, rep: int,
                    fillers: dict[str, Path] | None = None) -> Results:
    """On frames the page measures never touched (repetition ``rep``'s), a new host per frame; with
    ``fillers``, each new host's ``CACHE_ROOT/storage`` holds that folder's files (a host that has served a while)."""
    results: Results = {}
    suffix = f", {sum(1 for _ in next(iter(fillers.values())).rglob('*.png'))} files cached" if fillers else ""
    frames = {b.name: b.frames(rep) for b in backends}
    # Each host's first box and its measured frame: frames no host has fetched yet.
    picks = np.linspace(0, len(frames["local"]) - 1, 2 * hosts).round().astype(int).reshape(hosts, 2)
    for n, (w, i) in enumerate(picks):
        for b in turns(backends, n):
            app = b.host()
            cache = Path(app.config["CACHE_ROOT"]) / "storage"
            if fillers:
                cache.parent.mkdir(parents=True)
                fillers[b.name].rename(cache)
            client, sent = b.signed_in(app), bucket_requests(app)
            forget_memory()
            before = sent()  # the host's first box, on another frame: its S3 client, connections, cache count
            add(results, "new host's first box" + suffix, b, box(client, frames[b.name][w], f"warm{n}"),
                sent() - before)
            forget_memory()
            for name, key in (("first touch", "first"), *(("cached", f"again{k}") for k in range(again))):
                before = sent()
                add(results, name + suffix, b, box(client, frames[b.name][i], key), sent() - before)
            if fillers:
                cache.rename(fillers[b.name])  # on to the next host, with what this one fetched
            with app.app_context():
                db.engine.dispose()
    return results


def filler(folder: Path, count: int) -> Path:
    """``count`` small files laid out as a bucket's media copies are (what a host's cache holds after a while)."""
    for i in range(count):
        name = f"{i:064x}"
        path = folder / "media" / name[-2:] / f"{name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"\0" * 1024)
    return folder


def measure_checkpoints(backends: list[Backend], repeats: int, folder: Path) -> Results:
    path = folder / "egonet-lite.pt"
    torch.save(build_model("egonet-lite").state_dict(), path)
    print(f"checkpoint: egonet-lite state_dict, {path.stat().st_size / 1e6:.1f} MB")
    results: Results = {}
    sent = {b.name: bucket_requests(b.main) for b in backends}
    for rep in range(repeats):
        for b in turns(backends, rep):
            key = f"checkpoints/bench/{rep}/egonet-lite.pt"
            with b.main.app_context():
                before, start = sent[b.name](), time.perf_counter()
                store().put_file(key, path)
                add(results, "save", b, ms_since(start), sent[b.name]() - before)
            app = b.host()
            on_host = bucket_requests(app)  # the host's client made, as after its first request
            with app.app_context():
                for name in ("load first", "load cached"):
                    before, start = on_host(), time.perf_counter()
                    torch.load(store().local_path(key), map_location="cpu", weights_only=True)
                    add(results, name, b, ms_since(start), on_host() - before)
                db.engine.dispose()
    return results


# --------------------------------------------------------------------------


def load() -> str:
    return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg()) + f" on {os.cpu_count()} CPUs"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="imports of each source, and checkpoint round trips")
    parser.add_argument("--copies", type=int, default=4, help="copies of each real frame per import")
    parser.add_argument("--synthetic", type=int, default=24, help="synthetic frames per import")
    parser.add_argument("--hosts", type=int, default=8, help="new hosts for the GrabCut first touch")
    parser.add_argument("--again", type=int, default=5, help="cached boxes per new host, after its first touch")
    parser.add_argument("--cache-files", type=int, default=20_000,
                        help="files in a new host's cache for the second first-touch measure (0: skip it)")
    parser.add_argument("--gets", type=int, default=10, help="cached requests per frame and image")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    torch.set_num_threads(1)
    print(f"start: {load()}")
    results: dict[str, Results] = {}
    with tempfile.TemporaryDirectory(prefix="egonet-bench-storage-") as tmp:
        tmp = Path(tmp)
        weed = SeaweedFS(tmp / "seaweedfs").start()
        try:
            weed.create_bucket(BUCKET)
            os.environ.update(weed.environ())
            inputs = []
            for rep in range(args.repeats):
                folders = real_folders(tmp / "input", rep, args.copies)
                folders["synthetic"] = synthetic_folder(tmp / "input", rep, args.synthetic)
                inputs.append(folders)
            backends = [Backend("local", str(tmp / "local-storage"), tmp / "local"),
                        Backend("s3", f"s3://{BUCKET}/{uuid.uuid4().hex[:8]}", tmp / "s3")]
            print(f"stores: {backends[0].storage_url} and {backends[1].storage_url} (SeaweedFS at {weed.endpoint})")
            results["import (frames/s)"] = measure_import(backends, inputs)
            results["page (ms)"] = measure_pages(backends, args.gets)
            results["GrabCut box (ms)"] = measure_grabcut(backends, args.hosts, args.again, args.repeats - 1)
            if args.cache_files:
                fillers = {b.name: filler(tmp / f"filler-{b.name}", args.cache_files) for b in backends}
                results["GrabCut box (ms)"] |= measure_grabcut(backends, args.hosts, args.again, max(args.repeats - 2, 0),
                                                              fillers)
            results["checkpoint (ms)"] = measure_checkpoints(backends, args.repeats, tmp)
            for b in backends:
                with b.main.app_context():
                    db.engine.dispose()
        finally:
            weed.stop()
    print(f"end: {load()}\n")
    report(results)
    return 0


def report(results: dict[str, Results]) -> None:
    """Medians, p95 and the ratio S3 / local, the bucket's requests per value, and the goals."""
    print(f"{'measure':50s} {'local p50':>9s} {'p95':>7s} {'s3 p50':>8s} {'p95':>7s} {'s3/local':>8s} {'n':>4s} "
          f"{'S3 req':>6s}  goal")
    for group, measures in results.items():
        for name, by in measures.items():
            local, s3 = by["local"], by["s3"]
            ratio, ratio95 = statistics.median(s3) / statistics.median(local), pct(s3, 95) / pct(local, 95)
            goal = ""
            if group.startswith("import"):
                goal = f"s3 >= 0.5 x local: {'met' if ratio >= 0.5 else 'NOT met'}"
            elif group.startswith("page") and not name.endswith("first"):
                goal = f"p50 and p95 within 10 %: {'met' if max(ratio, ratio95) <= 1.10 else 'NOT met'}"
            elif name.startswith("cached"):
                goal = f"p50 within 10 %: {'met' if ratio <= 1.10 else 'NOT met'}"
            elif name.startswith("first touch"):
                extra = statistics.median(s3) - statistics.median(local)
                goal = f"p50 within 150 ms: {extra:+.0f} ms, {'met' if extra <= 150 else 'NOT met'}"
            print(f"{group + ': ' + name:50s} {statistics.median(local):9.1f} {pct(local, 95):7.1f} "
                  f"{statistics.median(s3):8.1f} {pct(s3, 95):7.1f} {ratio:8.2f} {len(s3):4d} "
                  f"{statistics.median(by['requests']):6.1f}  {goal}")
    print("(S3 req: the median number of HTTP requests the host sent to the bucket per value: per frame for imports)")


if __name__ == "__main__":
    raise SystemExit(main())
