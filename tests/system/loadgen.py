"""Simulated users against the production server on PostgreSQL.

``run_load`` sets up a private PostgreSQL schema with demo frames, a study
and accounts, starts gunicorn (``app:create_app()``) and runs the users for
``duration`` seconds:

* annotators browse activities and frames, open the labelling page, draw a
  GrabCut box around the frame's action-object (its demo ground truth, 5 %
  loose each side) and three strokes (foreground on the object, background
  in the box beside it), and save masks (with version checks);
* participants answer study trials;
* optionally (``abuser=True``) one more annotator sends the largest GrabCut
  calls the server allows, back to back with no think time: a box over all
  but the border of a frame of the largest allowed size, then strokes with
  the most points and the widest radius allowed, zig-zagging over it. Their
  latencies are kept under ``ABUSE_BOX`` / ``ABUSE_STROKE``, apart from the
  other users'.

Users arrive one after another over the first ``ramp`` seconds (like
locust's spawn rate; a thundering herd of users starting in the same
millisecond is another test), and each waits a human-like think time between
actions, times ``pace`` (1 for the figures; the CI test's users think
faster, so the same requests come closer together). The result holds every
request's latency, the errors, and how many acknowledged saves are missing
from the database afterwards.

Used by ``bench/load.py`` (the figures) and ``tests/system/test_load.py``
(no errors, nothing lost, in CI).
"""

import asyncio
import random
import time
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import httpx
import numpy as np
from flask_migrate import upgrade

from app.extensions import db
from app.models import Activity, Annotation, Frame
from app.services import studies
from app.services.demo import create_demo
from app.services.ground_truth import ground_truths, mask_of
from app.services.importing import import_path
from app.services.labelling import stroke_pixels
from app.services.users import create_user
from tests.system.harness import (
    Server, drop_schema, make_app, participant_client, private_schema_url, rle, staff_client,
)

PASSWORD = "load-test-password"
BOX, STROKE = "POST /api/label/grabcut/box", "POST /api/label/grabcut/stroke"
ABUSE_BOX, ABUSE_STROKE = "abuser: largest box", "abuser: largest stroke"


@dataclass
class Stats:
    times: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    timeline: list[tuple[float, str, float]] = field(default_factory=list)  # (start, endpoint, seconds)
    errors: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    error_samples: list[str] = field(default_factory=list)

    async def call(self, client: httpx.AsyncClient, name: str, method: str, url: str, *, ok=(200,), **kwargs):
        start = time.perf_counter()
        try:
            response = await client.request(method, url, **kwargs)
        except httpx.HTTPError as exc:
            self.errors[name] += 1
            self.error_samples.append(f"{name}: {type(exc).__name__}")
            return None
        elapsed = time.perf_counter() - start
        self.times[name].append(elapsed)
        self.timeline.append((start, name, elapsed))
        if response.status_code not in ok:
            self.errors[name] += 1
            self.error_samples.append(f"{name}: {response.status_code} {response.text[:120]}")
            return None
        return response


@dataclass
class LoadResult:
    stats: Stats
    origin: float  # perf_counter() when the first user arrived
    elapsed: float  # seconds until the last user stopped
    saves: int  # acknowledged
    lost: int  # acknowledged saves missing or different in the database afterwards
    description: str


@dataclass(frozen=True)
class Target:
    """A frame as an annotator sees it: where the box goes, where strokes can go."""

    frame_id: int
    height: int
    width: int
    box: list[float]
    fg: np.ndarray  # (N, 2) x, y on the object
    bg: np.ndarray  # (N, 2) x, y in the box, off the object


def target_of(frame_id: int, truth: np.ndarray, rng: np.random.Generator) -> Target:
    h, w = truth.shape
    if truth.any():
        ys, xs = np.nonzero(truth)
        x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
    else:  # no action-object: a box in the middle
        x0, x1, y0, y1 = int(w * 0.3), int(w * 0.6), int(h * 0.3), int(h * 0.7)
        truth = np.zeros_like(truth)
        truth[y0:y1, x0:x1] = True
    px, py = max(3, round(0.05 * (x1 - x0))), max(3, round(0.05 * (y1 - y0)))
    box = [max(0, x0 - px), max(0, y0 - py), min(w, x1 + px), min(h, y1 + py)]
    inside = np.zeros_like(truth)
    inside[box[1] : box[3], box[0] : box[2]] = True
    off = inside & ~truth

    def sample(where: np.ndarray) -> np.ndarray:
        ys, xs = np.nonzero(where)
        pick = rng.choice(len(xs), size=min(64, len(xs)), replace=False)
        return np.stack([xs[pick], ys[pick]], axis=1).astype(float)

    return Target(frame_id, h, w, [float(v) for v in box], sample(truth), sample(off if off.any() else inside))


async def think(rng: random.Random, pace: float, low=1.0, high=3.0):
    await asyncio.sleep(pace * rng.uniform(low, high))


async def annotator(base, cookies, headers, targets, activities, stats, saves, deadline, seed, delay, pace):
    rng = random.Random(seed)
    await asyncio.sleep(delay)
    async with httpx.AsyncClient(base_url=base, cookies=cookies, headers=headers, timeout=30) as client:
        versions: dict[int, int] = {}
        while time.monotonic() < deadline:
            frame = rng.choice(targets)
            fid, h, w = frame.frame_id, frame.height, frame.width
            await stats.call(client, "GET /api/activities", "GET", "/api/activities")
            await stats.call(client, "GET /activities/<id>", "GET", f"/activities/{rng.choice(activities)}")
            await think(rng, pace)
            await stats.call(client, "GET /label/frames/<id>", "GET", f"/label/frames/{fid}")
            page = await stats.call(client, "GET /api/label/frames/<id>/annotation", "GET", f"/api/label/frames/{fid}/annotation")
            if page is not None:
                versions[fid] = page.json()["version"]
            await think(rng, pace)
            target = {"frame_id": fid, "instance": "o1"}
            await stats.call(client, BOX, "POST", "/api/label/grabcut/box", json={**target, "box": frame.box})
            for _ in range(3):
                await think(rng, pace, 2.0, 5.0)  # a person looks at the new mask before the next stroke
                label = rng.choice(["fg", "bg"])
                x, y = rng.choice(frame.fg if label == "fg" else frame.bg)
                stroke = {**target, "points": [[x, y], [x + 15, y + 10]], "label": label, "radius": 6}
                await stats.call(client, STROKE, "POST", "/api/label/grabcut/stroke", json=stroke)
            mask = np.zeros((h, w), bool)
            top = rng.randrange(0, h // 2)
            mask[top : top + h // 3, w // 4 : w // 2] = True
            body = {"version": versions.get(fid, 0), "instances": [{"key": "o1", "kind": "tactile", "mask": rle(mask)}]}
            saved = await stats.call(client, "PUT /api/label/frames/<id>/annotation", "PUT", f"/api/label/frames/{fid}/annotation", json=body)
            if saved is not None:
                versions[fid] = saved.json()["version"]
                saves.append((fid, versions[fid], mask))
            await think(rng, pace)


async def participant(base, cookies, headers, stats, deadline, seed, delay, pace):
    rng = random.Random(seed)
    await asyncio.sleep(delay)
    async with httpx.AsyncClient(base_url=base, cookies=cookies, headers=headers, timeout=30) as client:
        while time.monotonic() < deadline:
            current = await stats.call(client, "GET /s/api/current", "GET", "/s/api/current")
            if current is None or current.json()["trial"] is None:
                return
            trial = current.json()["trial"]
            await stats.call(client, "GET /s/trials/<id>/image", "GET", trial["image_url"])
            await think(rng, pace, 1.5, 4.0)
            click = {"x": rng.uniform(0, trial["width"] - 1), "y": rng.uniform(0, trial["height"] - 1), "rt_ms": 900.0}
            answer = {"clicks": [click], "none": False, "timed_out": False, "rt_ms": 1000.0, "events": []}
            await stats.call(client, "POST /s/api/trials/<id>", "POST", trial["submit_url"], json=answer)


@dataclass(frozen=True)
class Limits:
    """The largest GrabCut call the server accepts (from the app's config)."""

    frame_side: int
    stroke_points: int
    radius: float
    stroke_pixels: int  # what one object's strokes may sweep in all (labelling.stroke_pixels)

    @classmethod
    def of(cls, config) -> "Limits":
        return cls(int(config["MAX_FRAME_SIDE"]), int(config["GRABCUT_MAX_STROKE_POINTS"]),
                   float(config["GRABCUT_MAX_RADIUS"]), int(config["GRABCUT_MAX_STROKE_PIXELS"]))


def largest_stroke(limits: Limits) -> list[list[float]]:
    """A zig-zag over the whole frame with the widest brush: as many points
    as the stroke limits allow (the points cap, and the pixels one object's
    strokes may sweep), every point somewhere new."""
    side = limits.frame_side
    shape = (side, side)

    def zigzag(n: int) -> np.ndarray:
        t = np.linspace(0.0, 1.0, n)
        return np.stack([1 + (side - 3) * np.abs(((t * 40) % 2) - 1), 1 + (side - 3) * t], axis=1)

    low, high = 1, limits.stroke_points
    while low < high:  # the longest zig-zag within the sweep limit
        mid = (low + high + 1) // 2
        if stroke_pixels(shape, zigzag(mid), limits.radius) <= limits.stroke_pixels:
            low = mid
        else:
            high = mid - 1
    return zigzag(low).tolist()


def add_abuse_frame(instance: Path, side: int) -> int:
    """Import one ``side`` x ``side`` frame of smooth colour blobs with noise
    (no clear object: the graph cut's worst case); return its id."""
    rng = np.random.default_rng(5)
    small = rng.integers(0, 256, (12, 12, 3), dtype=np.uint8)
    image = cv2.resize(small, (side, side), interpolation=cv2.INTER_CUBIC)
    image = np.clip(image.astype(np.int16) + rng.integers(-20, 21, image.shape), 0, 255).astype(np.uint8)
    folder = instance / "abuse-frames"
    folder.mkdir()
    cv2.imwrite(str(folder / "00000.png"), image)
    import_path(folder, activity="abuse")
    return db.session.execute(db.select(Frame.id).where(Frame.width == side)).scalars().first()


async def abuser(base, cookies, headers, frame_id: int, limits: Limits, stats, deadline):
    """One annotator sending the largest allowed GrabCut calls in a loop, no
    think time: a box over all of the largest frame but a 16 px border (the
    least background GrabCut accepts), then the largest stroke (which uses up
    the object's sweep budget, so the next call is a box again). Like the
    annotators it finishes the cycle it started: a box slower than the whole
    run (10.6 s on a 2-core machine at load 10) is still followed by its stroke."""
    side = limits.frame_side
    target = {"frame_id": frame_id, "instance": "abuse"}
    box = {**target, "box": [16, 16, side - 16, side - 16]}
    stroke = {**target, "points": largest_stroke(limits), "label": "bg", "radius": limits.radius}
    async with httpx.AsyncClient(base_url=base, cookies=cookies, headers=headers, timeout=120) as client:
        while time.monotonic() < deadline:
            await stats.call(client, ABUSE_BOX, "POST", "/api/label/grabcut/box", json=box)
            await stats.call(client, ABUSE_STROKE, "POST", "/api/label/grabcut/stroke", json=stroke)


def count_lost(saves: list[tuple[int, int, np.ndarray]]) -> int:
    """How many frames' last acknowledged save is not what the database holds."""
    last: dict[int, tuple[int, np.ndarray]] = {}
    for fid, version, mask in saves:
        if version >= last.get(fid, (0, None))[0]:
            last[fid] = (version, mask)
    lost = 0
    for fid, (version, mask) in last.items():
        stored = db.session.execute(
            db.select(Annotation)
            .where(Annotation.frame_id == fid, Annotation.author_id.is_not(None))
            .order_by(Annotation.updated_at.desc())
        ).scalars().first()
        if stored is None or stored.version < version or (stored.version == version and not np.array_equal(mask_of(stored), mask)):
            lost += 1
    return lost


def run_load(
    postgres_url: str,
    instance: Path,
    *,
    users: int = 50,
    participants: int = 15,
    duration: float = 60.0,
    ramp: float = 10.0,
    workers: int = 4,
    threads: int = 4,
    size: tuple[int, int] = (1280, 960),
    abuse: bool = False,
    pace: float = 1.0,
) -> LoadResult:
    """Run ``users`` simulated users (``participants`` of them in a study) for
    ``duration`` seconds, thinking ``pace`` times a person's time; with
    ``abuse``, one more annotator sends the largest allowed GrabCut calls in a loop."""
    n_annotators = users - participants
    if n_annotators < 1 or participants < 0:
        raise ValueError(f"need at least one annotator: {users} users, {participants} participants")
    width, height = size
    url, schema = private_schema_url(postgres_url)
    app = make_app(url, instance)
    try:
        with app.app_context():
            upgrade()
            # Every frame labelled: the study draws all 5 frames of each activity, and
            # annotators box each frame's stored ground truth (ground_truths below).
            create_demo(frames_per_activity=5, unlabelled_fraction=0, seed=11, width=width, height=height)
            for i in range(n_annotators):
                create_user(f"load{i}", "annotator", PASSWORD)
            activities = list(db.session.execute(db.select(Activity.id)).scalars())
            study = studies.create_study(name="load", activity_ids=activities, frames_per_activity=5, seed=1)
            codes = [p.code for p in studies.add_participants(study, count=participants)]
            truths = ground_truths(db.session.execute(db.select(Frame.id)).scalars())
            pick = np.random.default_rng(0)
            frames = [target_of(fid, mask_of(a), pick) for fid, a in sorted(truths.items())]
            limits = Limits.of(app.config)
            if abuse:
                create_user("abuser", "annotator", PASSWORD)
                abuse_frame = add_abuse_frame(instance, limits.frame_side)
            db.session.remove()
        description = (f"gunicorn {workers} workers x {threads} threads on PostgreSQL; {len(frames)} frames of "
                       f"{width}x{height}; {n_annotators} annotators + {participants} participants arriving over {ramp:g} s")
        if abuse:
            description += (f"; plus one abuser: boxes on a {limits.frame_side}x{limits.frame_side} frame and strokes of "
                            f"{len(largest_stroke(limits))} points with radius {limits.radius:g}")
        server = Server(url, instance, workers=workers, threads=threads)
        try:
            sessions = []
            for i in range(n_annotators):
                with closing(staff_client(server.url, f"load{i}", PASSWORD)) as c:
                    sessions.append(("annotator", dict(c.cookies), dict(c.headers)))
            for code in codes:
                with closing(participant_client(server.url, code)) as c:
                    sessions.append(("participant", dict(c.cookies), dict(c.headers)))
            stats, saves = Stats(), []
            # Annotators and participants arrive interleaved, in a shuffled order; each
            # annotator labels its own frames, as in a real project (no version conflicts by design).
            arrival = list(range(len(sessions)))
            random.Random(0).shuffle(arrival)
            deadline = time.monotonic() + duration
            origin = time.perf_counter()
            jobs = []
            for i, (kind, cookies, headers) in enumerate(sessions):
                headers = {k: v for k, v in headers.items() if k.lower() in ("x-csrftoken", "accept")}
                delay = ramp * arrival[i] / len(sessions)
                if kind == "annotator":
                    mine = frames[i % n_annotators :: n_annotators] or frames[:1]
                    jobs.append(annotator(server.url, cookies, headers, mine, activities, stats, saves, deadline, i, delay, pace))
                else:
                    jobs.append(participant(server.url, cookies, headers, stats, deadline, i, delay, pace))

            if abuse:
                with closing(staff_client(server.url, "abuser", PASSWORD)) as c:
                    headers = {k: v for k, v in c.headers.items() if k.lower() in ("x-csrftoken", "accept")}
                    jobs.append(abuser(server.url, dict(c.cookies), headers, abuse_frame, limits, stats, deadline))

            async def run_all():
                await asyncio.wait_for(asyncio.gather(*jobs), timeout=duration + 120)

            # On a thread of its own: the caller may be running an event loop
            # already (a pytest session with Playwright's sync API is).
            with ThreadPoolExecutor(max_workers=1) as pool:
                pool.submit(asyncio.run, run_all()).result()
            elapsed = time.perf_counter() - origin
        finally:
            server.stop()
        with app.app_context():
            lost = count_lost(saves)
            db.session.remove()
    finally:
        with app.app_context():
            db.engine.dispose()
        drop_schema(postgres_url, schema)
    return LoadResult(stats, origin, elapsed, len(saves), lost, description)
