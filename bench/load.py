"""Load test: 50 concurrent users against the production server on PostgreSQL.

Starts gunicorn (``app:create_app()``) on a private PostgreSQL schema with
demo frames, then runs for ``--duration`` seconds:

* annotators browse activities and frames, open the labelling page, draw a
  GrabCut box and strokes, and save masks (with version checks);
* participants answer study trials.

Each simulated user waits a human-like think time between actions. At the
end it prints p50/p95 latency per endpoint, the errors, and checks that no
acknowledged save was lost. Goals (issue 6): non-GrabCut p95 < 300 ms,
GrabCut p95 < 500 ms, 0 errors, 0 lost saves.

    EGONET_TEST_POSTGRES_URL=postgresql://postgres@127.0.0.1:5432/test \\
        .venv/bin/python bench/load.py --users 50 --duration 60
"""

import argparse
import asyncio
import os
import random
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from contextlib import closing
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flask_migrate import upgrade  # noqa: E402
from pycocotools import mask as coco_mask  # noqa: E402

from tests.system.harness import Server, drop_schema, make_app, participant_client, private_schema_url, staff_client  # noqa: E402

PASSWORD = "load-test-password"
GRABCUT = ("POST /api/label/grabcut/box", "POST /api/label/grabcut/stroke")


class Stats:
    def __init__(self):
        self.times: dict[str, list[float]] = defaultdict(list)
        self.errors: dict[str, int] = defaultdict(int)
        self.error_samples: list[str] = []

    async def call(self, client: httpx.AsyncClient, name: str, method: str, url: str, *, ok=(200,), **kwargs):
        start = time.perf_counter()
        try:
            response = await client.request(method, url, **kwargs)
        except httpx.HTTPError as exc:
            self.errors[name] += 1
            self.error_samples.append(f"{name}: {type(exc).__name__}")
            return None
        self.times[name].append(time.perf_counter() - start)
        if response.status_code not in ok:
            self.errors[name] += 1
            self.error_samples.append(f"{name}: {response.status_code} {response.text[:120]}")
            return None
        return response


def rle(mask: np.ndarray) -> dict:
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in encoded["size"]], "counts": encoded["counts"].decode()}


async def think(rng: random.Random, low=1.0, high=3.0):
    await asyncio.sleep(rng.uniform(low, high))


async def annotator(base, cookies, headers, frames, activities, stats, saves, deadline, seed):
    rng = random.Random(seed)
    async with httpx.AsyncClient(base_url=base, cookies=cookies, headers=headers, timeout=30) as client:
        versions: dict[int, int] = {}
        while time.monotonic() < deadline:
            fid, h, w = rng.choice(frames)
            await stats.call(client, "GET /api/activities", "GET", "/api/activities")
            await stats.call(client, "GET /activities/<id>", "GET", f"/activities/{rng.choice(activities)}")
            await think(rng)
            await stats.call(client, "GET /label/frames/<id>", "GET", f"/label/frames/{fid}")
            page = await stats.call(client, "GET /api/label/frames/<id>/annotation", "GET", f"/api/label/frames/{fid}/annotation")
            if page is not None:
                versions[fid] = page.json()["version"]
            await think(rng)
            target = {"frame_id": fid, "instance": "o1"}
            box = [w * 0.3, h * 0.3, w * 0.6, h * 0.7]
            await stats.call(client, GRABCUT[0], "POST", "/api/label/grabcut/box", json={**target, "box": box})
            for _ in range(3):
                await think(rng, 2.0, 5.0)  # a person looks at the new mask before the next stroke
                x, y = rng.uniform(w * 0.35, w * 0.55), rng.uniform(h * 0.35, h * 0.65)
                stroke = {**target, "points": [[x, y], [x + 15, y + 10]], "label": rng.choice(["fg", "bg"]), "radius": 6}
                await stats.call(client, GRABCUT[1], "POST", "/api/label/grabcut/stroke", json=stroke)
            mask = np.zeros((h, w), bool)
            top = rng.randrange(0, h // 2)
            mask[top : top + h // 3, w // 4 : w // 2] = True
            body = {"version": versions.get(fid, 0), "instances": [{"key": "o1", "kind": "tactile", "mask": rle(mask)}]}
            saved = await stats.call(client, "PUT /api/label/frames/<id>/annotation", "PUT", f"/api/label/frames/{fid}/annotation", json=body)
            if saved is not None:
                versions[fid] = saved.json()["version"]
                saves.append((fid, versions[fid], mask))
            await think(rng)


async def participant(base, cookies, headers, stats, deadline, seed):
    rng = random.Random(seed)
    async with httpx.AsyncClient(base_url=base, cookies=cookies, headers=headers, timeout=30) as client:
        while time.monotonic() < deadline:
            current = await stats.call(client, "GET /s/api/current", "GET", "/s/api/current")
            if current is None or current.json()["trial"] is None:
                return
            trial = current.json()["trial"]
            await stats.call(client, "GET /s/trials/<id>/image", "GET", trial["image_url"])
            await think(rng, 1.5, 4.0)
            click = {"x": rng.uniform(0, trial["width"] - 1), "y": rng.uniform(0, trial["height"] - 1), "rt_ms": 900.0}
            answer = {"clicks": [click], "none": False, "timed_out": False, "rt_ms": 1000.0, "events": []}
            await stats.call(client, "POST /s/api/trials/<id>", "POST", trial["submit_url"], json=answer)


def percentile(values, q):
    return float(np.percentile(values, q)) if values else float("nan")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--users", type=int, default=50)
    parser.add_argument("--participants", type=int, default=15, help="how many of the users are study participants")
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--workers", type=int, default=4)
    parser.add_argument("--threads", type=int, default=4)
    parser.add_argument("--size", default="640x480", help="demo frame size")
    args = parser.parse_args()
    base_url = os.environ.get("EGONET_TEST_POSTGRES_URL")
    if not base_url:
        sys.exit("set EGONET_TEST_POSTGRES_URL (e.g. postgresql://postgres@127.0.0.1:5432/test)")
    width, height = (int(v) for v in args.size.split("x"))
    n_annotators = args.users - args.participants

    url, schema = private_schema_url(base_url)
    instance = Path(tempfile.mkdtemp(prefix="egonet-load-"))
    app = make_app(url, instance)
    from app.extensions import db
    from app.models import Activity, Annotation, Frame
    from app.services import studies
    from app.services.demo import create_demo
    from app.services.ground_truth import mask_of
    from app.services.users import create_user

    with app.app_context():
        upgrade()
        create_demo(frames_per_activity=5, seed=11, width=width, height=height)
        for i in range(n_annotators):
            create_user(f"load{i}", "annotator", PASSWORD)
        activities = list(db.session.execute(db.select(Activity.id)).scalars())
        study = studies.create_study(name="load", activity_ids=activities, frames_per_activity=5, seed=1)
        codes = [p.code for p in studies.add_participants(study, count=args.participants)]
        frames = [(f.id, f.height, f.width) for f in db.session.execute(db.select(Frame)).scalars()]
    server = Server(url, instance, workers=args.workers, threads=args.threads)
    print(f"server: gunicorn {args.workers} workers x {args.threads} threads on PostgreSQL; "
          f"{len(frames)} frames of {width}x{height}; {n_annotators} annotators + {args.participants} participants")
    try:
        sessions = []
        for i in range(n_annotators):
            with closing(staff_client(server.url, f"load{i}", PASSWORD)) as c:
                sessions.append(("annotator", dict(c.cookies), dict(c.headers)))
        for code in codes:
            with closing(participant_client(server.url, code)) as c:
                sessions.append(("participant", dict(c.cookies), dict(c.headers)))
        stats, saves = Stats(), []
        deadline = time.monotonic() + args.duration
        # Each annotator labels its own frames, as in a real project (no version conflicts by design).
        jobs = []
        for i, (kind, cookies, headers) in enumerate(sessions):
            headers = {k: v for k, v in headers.items() if k.lower() in ("x-csrftoken", "accept")}
            if kind == "annotator":
                mine = frames[i % n_annotators :: n_annotators] or frames[:1]
                jobs.append(annotator(server.url, cookies, headers, mine, activities, stats, saves, deadline, i))
            else:
                jobs.append(participant(server.url, cookies, headers, stats, deadline, i))
        started = time.monotonic()
        async def run_all():
            await asyncio.wait_for(asyncio.gather(*jobs), timeout=args.duration + 120)

        asyncio.run(run_all())
        elapsed = time.monotonic() - started
    finally:
        server.stop()

    lost = 0
    with app.app_context():
        last: dict[int, tuple[int, np.ndarray]] = {}
        for fid, version, mask in saves:
            if version >= last.get(fid, (0, None))[0]:
                last[fid] = (version, mask)
        for fid, (version, mask) in last.items():
            stored = db.session.execute(db.select(Annotation).where(Annotation.frame_id == fid, Annotation.author_id.is_not(None)).order_by(Annotation.updated_at.desc())).scalars().first()
            if stored is None or stored.version < version or (stored.version == version and not np.array_equal(mask_of(stored), mask)):
                lost += 1
        db.session.remove()
        db.engine.dispose()
    drop_schema(base_url, schema)

    total = sum(len(v) for v in stats.times.values())
    print(f"\n{total} requests in {elapsed:.0f} s ({total / elapsed:.1f}/s), {len(saves)} saves acknowledged\n")
    print(f"{'endpoint':44s} {'n':>6s} {'p50 ms':>8s} {'p95 ms':>8s} {'errors':>7s}")
    for name in sorted(stats.times):
        t = [1000 * v for v in stats.times[name]]
        print(f"{name:44s} {len(t):6d} {statistics.median(t):8.1f} {percentile(t, 95):8.1f} {stats.errors[name]:7d}")
    other = [1000 * v for n, ts in stats.times.items() if n not in GRABCUT for v in ts]
    grabcut = [1000 * v for n in GRABCUT for v in stats.times.get(n, [])]
    errors = sum(stats.errors.values())
    print(f"\nnon-GrabCut p95 {percentile(other, 95):.0f} ms (goal < 300), GrabCut p95 {percentile(grabcut, 95):.0f} ms (goal < 500), "
          f"{errors} errors (goal 0), {lost} lost saves (goal 0)")
    for sample in stats.error_samples[:10]:
        print("  error:", sample)


if __name__ == "__main__":
    main()
