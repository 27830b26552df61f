"""Benchmark: GrabCut box -> mask and stroke -> mask through the HTTP API.

What an annotator waits for on the labelling page, measured end to end: the
production server (gunicorn, several workers, ``app:create_app()``) on
PostgreSQL, a signed-in annotator's JSON request with its CSRF token, the
session restored as the app does it, and the PNG mask back. Every request
opens a new connection, so gunicorn hands it to any worker, and the server
runs with ``GRABCUT_CACHE_BYTES=0``, so no worker keeps a session in memory:
each stroke restores its session from the state in the database (and the
frame's image and depth from the media files or the worker's image cache)
— the slow path of a multi-worker deployment. ``--keep-sessions`` measures
the usual path instead (a keep-alive connection stays with one worker, which
keeps the session).

Frames (the real ones of ``bench_grabcut.real_cases``, stored as the app
stores them):

* ``rgbd-chair``: ``shared/data/rgbd-primesense`` imported with the
  importer (640x480 RGB-D; the chair of frame 00001, truth drawn by hand),
  boxed with depth (the default on a frame with depth) and with
  ``use_depth: false``;
* ``rgbd-chair@1408x1408``: the same frame and depth scaled up;
* ``real-*``: the first-person frames of ``shared/data/egonet-samples``
  (no depth) at 640x480 and 1408x1408, with an object pasted in (its mask
  is the truth).

Before the measured frames, every worker runs a box and a stroke on the
first frame's mirror image (not counted): the measured frames stay new to
the workers, but no worker's first stroke ever is timed.

Each gets a loose box (3-8 % each side), a tight one (2 px each side) and one
through the object, then up to ``--strokes`` corrective strokes placed by
``bench_grabcut``'s simulated annotator on the answer's largest error.
Plain ``cv2.grabCut`` (full resolution, in this process, one thread) runs
on the same boxes with its own strokes for the ratio.

Targets (issue 14): box -> mask <= 400 ms median, stroke -> mask p95 <= 100 ms.
The latency is the client's wall clock per request; the server's own time
(``Server-Timing``: wall clock, and the request thread's CPU time, which
other load on a shared machine inflates far less) is printed beside it.
The server runs with one BLAS thread per request (``OPENBLAS_NUM_THREADS=1``,
as a deployment with several workers should).

    EGONET_TEST_POSTGRES_URL=postgresql://postgres@127.0.0.1:5432/test \\
        .venv/bin/python bench/bench_label_http.py [--workers 4] [--strokes 5] [--no-plain] [--no-large]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

# One thread per request for numpy's BLAS in this process and the server's
# workers (inherited): the targets are per core, and gunicorn's workers x
# threads already share the cores.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.bench_grabcut import (  # noqa: E402
    BIG, REAL_FRAMES, RGBD_FRAMES, PlainMethod, Stroke, annotator_box, annotator_stroke, chair_frame, iou,
    real_frame, through_box, tight_box,
)
from tests.system.harness import Server, drop_schema, make_app, private_schema_url, staff_client  # noqa: E402

from flask_migrate import upgrade  # noqa: E402

from app.extensions import db  # noqa: E402
from app.models import Frame  # noqa: E402
from app.services.importing import FrameItem, add_frames, import_path  # noqa: E402
from app.services.users import create_user  # noqa: E402
from egonet import io  # noqa: E402

PASSWORD = "bench-label-http-password"
BOX_MS, STROKE_P95_MS = 400, 100


@dataclass
class Case:
    """A frame stored in the app, with what the simulated annotator knows of it."""

    name: str
    frame_id: int
    rgb: np.ndarray  # (H, W, 3) uint8, for plain grabCut
    truth: np.ndarray  # (H, W) bool
    depth_choices: tuple[bool, ...]  # the use_depth values to run


@dataclass
class Timings:
    box: list[float] = field(default_factory=list)  # ms, client wall clock
    box_server: list[float] = field(default_factory=list)  # ms, Server-Timing
    box_cpu: list[float] = field(default_factory=list)  # ms, the request thread's CPU time (Server-Timing)
    stroke: list[float] = field(default_factory=list)
    stroke_server: list[float] = field(default_factory=list)
    stroke_cpu: list[float] = field(default_factory=list)
    iou_box: list[float] = field(default_factory=list)
    iou_final: list[float] = field(default_factory=list)
    by_kind: dict[str, list[float]] = field(default_factory=dict)  # box kind -> box ms


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def store_frames(app, large: bool) -> tuple[list[Case], Case]:
    """Import the real frames into the app: the cases to run on them, and a
    frame for the warm-up (the first case's mirror image)."""
    cases = []
    with app.app_context():
        if RGBD_FRAMES.is_dir():
            import_path(RGBD_FRAMES, activity="room")
            chair = chair_frame()
            frame_id = db.session.execute(db.select(Frame.id).filter_by(index=1)).scalar_one()
            cases.append(Case(chair.name, frame_id, chair.rgb, chair.truth, (True, False)))
        else:
            print(f"(no RGB-D frames at {RGBD_FRAMES}: skipped)")
        made = []
        if RGBD_FRAMES.is_dir() and large:
            made.append((chair_frame(BIG), True))
        if REAL_FRAMES.is_dir():
            for i, p in enumerate(sorted(REAL_FRAMES.glob("*.jpg"))):
                made.append((real_frame(p, 200 + i, (640, 480)), False))
                if large:
                    made.append((real_frame(p, 200 + i, BIG), False))
        for k, (f, with_depth) in enumerate(made):
            item = FrameItem(f.name, k, f.name, rgb=f.rgb, depth_m=f.depth if with_depth else None)
            add_frames(activity="bench", sequence=f"s{k}", items=[item])
            frame_id = db.session.execute(db.select(Frame.id).filter_by(source_name=f.name)).scalar_one()
            cases.append(Case(f.name, frame_id, f.rgb, f.truth, (True, False) if with_depth else (False,)))
        first = cases[0]
        name, rgb, truth = first.name + "-mirror", first.rgb[:, ::-1].copy(), first.truth[:, ::-1].copy()
        depth = chair_frame().depth[:, ::-1].copy() if first.depth_choices[0] else None  # the chair comes first
        add_frames(activity="warm-up", sequence="warm-up", items=[FrameItem(name, 0, name, rgb=rgb, depth_m=depth)])
        frame_id = db.session.execute(db.select(Frame.id).filter_by(source_name=name)).scalar_one()
        warm = Case(name, frame_id, rgb, truth, first.depth_choices[:1])
        create_user("bench", "annotator", PASSWORD)
    return cases, warm


def post(client: httpx.Client, op: str, body: dict) -> tuple[np.ndarray, float, float, float]:
    """One GrabCut request: (mask, client ms, server wall ms, server CPU ms)."""
    t = time.perf_counter()
    response = client.post(f"/api/label/grabcut/{op}", json=body, headers={"Accept": "image/png"})
    ms = 1e3 * (time.perf_counter() - t)
    if response.status_code != 200:
        raise RuntimeError(f"{op}: {response.status_code} {response.text[:200]}")
    timing = dict(part.strip().split(";dur=") for part in response.headers["Server-Timing"].split(","))
    return io.decode_mask(response.content), ms, float(timing["grabcut"]), float(timing["cpu"])


def boxes_of(truth: np.ndarray) -> list[tuple[str, tuple[int, int, int, int]]]:
    loose = annotator_box(truth, np.random.default_rng(0))
    return [("loose", loose), ("tight", tight_box(truth)), ("through", through_box(loose))]


def part_in(truth: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The object's part inside ``box`` (what a box through the object should give)."""
    x0, y0, x1, y1 = box
    out = np.zeros_like(truth)
    out[y0:y1, x0:x1] = truth[y0:y1, x0:x1]
    return out


def run_http(client: httpx.Client, cases: list[Case], n_strokes: int) -> dict[str, Timings]:
    results: dict[str, Timings] = {}
    print(f"{'frame':26s} {'box':8s} {'depth':5s} {'box ms':>7s} {'cpu':>7s}  {'stroke ms (client/server CPU)':40s} "
          "IoU box -> final")
    for case in cases:
        for kind, box in boxes_of(case.truth):
            truth = part_in(case.truth, box)
            for use_depth in case.depth_choices:
                label = "http+depth" if use_depth else "http"
                t = results.setdefault(label, Timings())
                key = f"{kind}-{int(use_depth)}"
                mask, ms, server, cpu = post(client, "box", {"frame_id": case.frame_id, "instance": key,
                                                             "box": list(box), "use_depth": use_depth})
                t.box.append(ms)
                t.box_server.append(server)
                t.box_cpu.append(cpu)
                t.by_kind.setdefault(kind, []).append(ms)
                t.iou_box.append(iou(mask, truth))
                strokes = []
                for _ in range(n_strokes):
                    s = annotator_stroke(mask, truth)
                    if s is None:
                        break
                    mask, ms, server, cpu = post(client, "stroke", {
                        "frame_id": case.frame_id, "instance": key, "points": [list(p) for p in s.points],
                        "label": s.label, "radius": s.radius})
                    t.stroke.append(ms)
                    t.stroke_server.append(server)
                    t.stroke_cpu.append(cpu)
                    strokes.append(f"{ms:.0f}/{cpu:.0f}")
                t.iou_final.append(iou(mask, truth))
                print(f"{case.name:26s} {kind:8s} {'on' if use_depth else 'off':5s} {t.box[-1]:7.0f} "
                      f"{t.box_cpu[-1]:7.0f}  {' '.join(strokes):40s} {t.iou_box[-1]:.3f} -> {t.iou_final[-1]:.3f}",
                      flush=True)
    return results


def run_plain(cases: list[Case], n_strokes: int) -> Timings:
    """Plain full-resolution cv2.grabCut on the same boxes, its own strokes."""
    t = Timings()
    for case in cases:
        for kind, box in boxes_of(case.truth):
            truth = part_in(case.truth, box)
            method = PlainMethod()
            start, cpu = time.perf_counter(), time.process_time()
            mask = method.box(case.rgb, box)
            t.box.append(1e3 * (time.perf_counter() - start))
            t.box_cpu.append(1e3 * (time.process_time() - cpu))
            t.by_kind.setdefault(kind, []).append(t.box[-1])
            t.iou_box.append(iou(mask, truth))
            for _ in range(n_strokes):
                s: Stroke | None = annotator_stroke(mask, truth)
                if s is None:
                    break
                start, cpu = time.perf_counter(), time.process_time()
                mask = method.stroke(s)
                t.stroke.append(1e3 * (time.perf_counter() - start))
                t.stroke_cpu.append(1e3 * (time.process_time() - cpu))
            t.iou_final.append(iou(mask, truth))
    return t


def warm_up(client: httpx.Client, case: Case, workers: int) -> None:
    """Let every worker run a box and a stroke once (not counted), on a frame
    that is not measured (the measured frames stay unseen by the workers)."""
    box = tight_box(case.truth)
    for i in range(2 * workers):
        mask, *_ = post(client, "box", {"frame_id": case.frame_id, "instance": f"warm{i}", "box": list(box),
                                        "use_depth": case.depth_choices[0]})
        s = annotator_stroke(mask, part_in(case.truth, box))
        if s is not None:
            post(client, "stroke", {"frame_id": case.frame_id, "instance": f"warm{i}",
                                    "points": [list(p) for p in s.points], "label": s.label, "radius": s.radius})


def breakdown(app, cases: list[Case], n_strokes: int) -> None:
    """Where a request's server time goes, in-process on the same database:
    the tight box and its strokes on each kind of frame, every session
    restored from the database (the HTTP run's slow path), timed by phase
    in this process's CPU time.
    ``engine`` is GrabCutSession.box / stroke (after a restore it also
    rebuilds the ROI's guides, which a cached session keeps); ``restore`` is
    decoding the state, or for a box making the new session (with the frame
    and depth from this worker's cache after their first use);
    ``other``: the lock file, checks, the request's own Python."""
    from unittest import mock

    from app.services.labelling import grabcut as service
    from app.services.users import find_user
    from egonet.grabcut import GrabCutSession

    spent: dict[str, float] = {}

    def timed(name, fn):
        def wrapper(*args, **kwargs):
            t = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] = spent.get(name, 0.0) + 1e3 * (time.process_time() - t)
        return wrapper

    patches = [
        mock.patch.object(GrabCutSession, "box", timed("engine", GrabCutSession.box)),
        mock.patch.object(GrabCutSession, "stroke", timed("engine", GrabCutSession.stroke)),
        mock.patch.object(service, "_load_session", timed("restore", service._load_session)),
        mock.patch.object(service, "_new_session", timed("restore", service._new_session)),
        mock.patch.object(service, "_dump_state", timed("save state", service._dump_state)),
        mock.patch.object(service, "_state_row", timed("database", service._state_row)),
        mock.patch.object(service.db.session, "commit", timed("database", service.db.session.commit)),
    ]
    app.config["GRABCUT_CACHE_BYTES"] = 0
    print("\nwhere the server's time goes (in-process, sessions restored from the database; CPU ms, "
          "which other load on the machine inflates far less than wall time):")
    print(f"{'frame':26s} {'depth':5s} {'op':7s} {'total':>6s} {'engine':>7s} {'restore':>8s} {'save':>5s} "
          f"{'db':>5s} {'PNG':>5s} {'other':>6s}")
    picked = {}
    for case in cases:  # one frame of each size, with and without depth
        picked.setdefault((case.rgb.shape, case.depth_choices), case)
    with app.app_context(), contextlib.ExitStack() as stack:
        for p in patches:
            stack.enter_context(p)
        user = find_user("bench")  # (and the database connection opened outside the timings)
        for case in picked.values():
            frame = db.session.get(Frame, case.frame_id)
            box = tight_box(case.truth)
            truth = part_in(case.truth, box)
            for use_depth in case.depth_choices:
                key = f"prof{int(use_depth)}"
                mask = None
                for i in range(n_strokes + 1):
                    s = annotator_stroke(mask, truth) if i else None
                    if i and s is None:
                        break
                    spent.clear()
                    t = time.process_time()
                    if i == 0:
                        result = service.grabcut_box(frame, user, key, box, use_depth=use_depth)
                    else:
                        result = service.grabcut_stroke(frame, user, key, points=s.points,
                                                        label=s.label, radius=s.radius)
                    t_png = time.process_time()
                    io.encode_png(result.mask)
                    png = 1e3 * (time.process_time() - t_png)
                    total = 1e3 * (time.process_time() - t)
                    mask = result.mask
                    parts = [spent.get(k, 0.0) for k in ("engine", "restore", "save state", "database")]
                    other = total - sum(parts) - png
                    print(f"{case.name:26s} {'on' if use_depth else 'off':5s} {'box' if i == 0 else 'stroke':7s} "
                          f"{total:6.0f} {parts[0]:7.0f} {parts[1]:8.1f} {parts[2]:5.1f} {parts[3]:5.1f} {png:5.1f} "
                          f"{other:6.1f}", flush=True)


def load() -> str:
    return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg()) + f" on {os.cpu_count()} CPUs"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--workers", type=int, default=4, help="gunicorn workers")
    parser.add_argument("--threads", type=int, default=2, help="threads per worker")
    parser.add_argument("--strokes", type=int, default=5, help="corrective strokes per box")
    parser.add_argument("--no-plain", action="store_true", help="skip plain cv2.grabCut (and the ratio)")
    parser.add_argument("--no-large", action="store_true", help="skip the 1408x1408 frames")
    parser.add_argument("--keep-sessions", action="store_true",
                        help="keep-alive and the workers' session cache on (the usual path, not the restore)")
    parser.add_argument("--breakdown", action="store_true",
                        help="then time one box and two strokes per kind of frame in-process, by phase")
    args = parser.parse_args(argv)
    postgres_url = os.environ.get("EGONET_TEST_POSTGRES_URL", "postgresql://postgres@127.0.0.1:5432/test")
    if not (RGBD_FRAMES.is_dir() or REAL_FRAMES.is_dir()):
        sys.exit(f"no real frames under {RGBD_FRAMES.parent}")
    cv2.setNumThreads(1)  # plain grabCut per core, as the engine benchmark

    print(f"start: {load()}")
    database_url, schema = private_schema_url(postgres_url)
    try:
        with tempfile.TemporaryDirectory(prefix="egonet-label-http-") as folder:
            instance = Path(folder)
            app = make_app(database_url, instance)
            with app.app_context():
                upgrade()
            cases, warm = store_frames(app, not args.no_large)
            if not args.keep_sessions:
                os.environ["FLASK_GRABCUT_CACHE_BYTES"] = "0"  # every operation restores from the database
            server = Server(database_url, instance, workers=args.workers, threads=args.threads)
            try:
                options = {} if args.keep_sessions else {"limits": httpx.Limits(max_keepalive_connections=0)}
                client = staff_client(server.url, "bench", PASSWORD, timeout=60, **options)
                try:
                    warm_up(client, warm, args.workers)
                    path = "keep-alive, sessions cached" if args.keep_sessions else \
                        "a new connection per request, every session restored from PostgreSQL"
                    print(f"\ngunicorn {args.workers} workers x {args.threads} threads, {path}")
                    results = run_http(client, cases, args.strokes)
                finally:
                    client.close()
            finally:
                server.stop()
            if args.breakdown:
                breakdown(app, cases, min(args.strokes, 2))
    finally:
        drop_schema(postgres_url, schema)
    if not args.no_plain:
        print("\nplain cv2.grabCut (full resolution, one thread) on the same boxes ...", flush=True)
        results["plain"] = run_plain(cases, args.strokes)

    print(f"\nend: {load()}")
    print(f"\n{'method':11s} {'box p50':>8s} {'p95':>6s} {'cpu p50':>8s} {'p95':>6s} | {'stroke p50':>10s} {'p95':>6s} "
          f"{'cpu p50':>8s} {'p95':>6s} {'n':>4s} | box p50 loose/tight/through | IoU box, final | targets (wall)")
    for label, t in results.items():
        kinds = "/".join(f"{pct(t.by_kind[k], 50):.0f}" for k in ("loose", "tight", "through"))
        met = "" if label == "plain" else (
            "met" if pct(t.box, 50) <= BOX_MS and pct(t.stroke, 95) <= STROKE_P95_MS else "NOT met")
        print(f"{label:11s} {pct(t.box, 50):8.0f} {pct(t.box, 95):6.0f} {pct(t.box_cpu, 50):8.0f} {pct(t.box_cpu, 95):6.0f} | "
              f"{pct(t.stroke, 50):10.1f} {pct(t.stroke, 95):6.1f} {pct(t.stroke_cpu, 50):8.1f} "
              f"{pct(t.stroke_cpu, 95):6.1f} {len(t.stroke):4d} | "
              f"{kinds:27s} | {np.mean(t.iou_box):.3f}, {np.mean(t.iou_final):.3f} | {met}")
    print("(client wall clock per request; cpu: the server's request thread (Server-Timing), for plain this "
          "process's CPU time)")
    if "plain" in results:
        p = results["plain"]
        for label in (k for k in results if k != "plain"):
            t = results[label]
            print(f"ratio plain / {label}: box p50 {pct(p.box, 50) / pct(t.box, 50):.1f}x, "
                  f"stroke p50 {pct(p.stroke, 50) / pct(t.stroke, 50):.1f}x, p95 {pct(p.stroke, 95) / pct(t.stroke, 95):.1f}x"
                  f"; CPU box p50 {pct(p.box_cpu, 50) / pct(t.box_cpu, 50):.1f}x, stroke p95 "
                  f"{pct(p.stroke_cpu, 95) / pct(t.stroke_cpu, 95):.1f}x (plain: in-process on the same boxes, its own strokes)")
    print(f"targets: box p50 <= {BOX_MS} ms, stroke p95 <= {STROKE_P95_MS} ms, through HTTP")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
