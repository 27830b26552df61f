"""kill -9 the production server mid-burst: nothing acknowledged is lost.

gunicorn serves the app on PostgreSQL. Annotators save masks and
participants answer trials as fast as they can; after a second the whole
server is killed with SIGKILL and started again. Every save and trial that
was answered 2xx must be in the database with its content, and the media
folder must agree with the database (no missing files; the orphans a crash
can leave are found and removed by ``flask egonet media-check``).
"""

import hashlib
from contextlib import closing
import os
import threading
import time

import httpx
import numpy as np
import pytest
from flask_migrate import upgrade

from app.extensions import db
from app.models import Activity, Annotation, Frame
from app.models.studies import Trial
from app.services import media
from app.services import studies as study_service
from app.services.demo import create_demo
from app.services.ground_truth import mask_of
from app.services.users import create_user
from tests.system.harness import Server, drop_schema, make_app, participant_client, private_schema_url, rle, staff_client

POSTGRES_URL = os.environ.get("EGONET_TEST_POSTGRES_URL")
PASSWORD = "crash-test-password"
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not POSTGRES_URL, reason="the crash test runs on PostgreSQL (EGONET_TEST_POSTGRES_URL)"),
]


def square(shape, step: int) -> np.ndarray:
    mask = np.zeros(shape, bool)
    s = 5 + step % 40
    mask[10 : 10 + s, 20 : 20 + s] = True
    return mask


def digest(mask: np.ndarray) -> str:
    return hashlib.sha256(np.packbits(mask).tobytes() + str(mask.shape).encode()).hexdigest()


@pytest.fixture
def deployment(tmp_path):
    url, schema = private_schema_url(POSTGRES_URL)
    app = make_app(url, tmp_path)
    with app.app_context():
        upgrade()
        create_demo(frames_per_activity=4, seed=5, width=160, height=120)
        for i in range(4):
            create_user(f"annotator{i}", "annotator", PASSWORD)
        activity_ids = list(db.session.execute(db.select(Activity.id)).scalars())
        study = study_service.create_study(name="crash", activity_ids=activity_ids, frames_per_activity=3, seed=3)
        people = study_service.add_participants(study, count=4)
        codes = [p.code for p in people]
        frames = [(f.id, f.height, f.width) for f in db.session.execute(db.select(Frame).order_by(Frame.id)).scalars()]
    yield {"url": url, "app": app, "instance": tmp_path, "codes": codes, "frames": frames}
    with app.app_context():
        db.session.remove()
        db.engine.dispose()  # close pooled connections before the schema goes
    drop_schema(POSTGRES_URL, schema)


ERRORS: list[BaseException] = []


def annotator(base, name, frames, acked, stop):
    try:
        with closing(staff_client(base, name, PASSWORD, timeout=10)) as client:
            _annotate(client, name, frames, acked, stop)
    except httpx.HTTPError:
        return  # the server was killed
    except BaseException as exc:  # surfaced by the test
        ERRORS.append(exc)


def _annotate(client, name, frames, acked, stop):
    versions = {fid: 0 for fid, _, _ in frames}
    step = 0
    while not stop.is_set():
        for fid, h, w in frames:
            step += 1
            mask = square((h, w), step)
            body = {"version": versions[fid], "instances": [{"key": "o1", "kind": "tactile", "mask": rle(mask)}]}
            response = client.put(f"/api/label/frames/{fid}/annotation", json=body)
            if response.status_code == 200:
                versions[fid] = response.json()["version"]
                acked.append((name, fid, versions[fid], digest(mask)))
            elif response.status_code != 409:
                raise AssertionError(f"save answered {response.status_code}: {response.text[:200]}")


def participant(base, code, acked, stop):
    try:
        with closing(participant_client(base, code, timeout=10)) as client:
            _answer(client, code, acked, stop)
    except httpx.HTTPError:
        return
    except BaseException as exc:
        ERRORS.append(exc)


def _answer(client, code, acked, stop):
    while not stop.is_set():
        state = client.get("/s/api/current").json()
        trial = state["trial"]
        if trial is None:
            return
        clicks = [{"x": trial["width"] / 3, "y": trial["height"] / 2, "rt_ms": 420.0}]
        answer = {"clicks": clicks, "none": False, "timed_out": False, "rt_ms": 450.0, "events": []}
        response = client.post(trial["submit_url"], json=answer)
        if response.status_code == 200:
            acked.append((code, trial["id"]))


def test_kill_9_mid_burst_loses_nothing_acknowledged(deployment):
    app, frames = deployment["app"], deployment["frames"]
    server = Server(deployment["url"], deployment["instance"], workers=2, threads=4)
    saves, trials, stop = [], [], threading.Event()
    threads = [
        threading.Thread(target=annotator, args=(server.url, f"annotator{i}", frames[i::4], saves, stop))
        for i in range(4)
    ] + [threading.Thread(target=participant, args=(server.url, code, trials, stop)) for code in deployment["codes"]]
    try:
        for t in threads:
            t.start()
        deadline = time.monotonic() + 30
        while len(saves) < 40 and time.monotonic() < deadline:
            time.sleep(0.05)
        server.kill()  # mid-burst: requests are in flight
        stop.set()
        for t in threads:
            t.join(timeout=30)
        assert not ERRORS, ERRORS
        assert len(saves) >= 40 and trials, f"too little traffic before the kill: {len(saves)} saves, {len(trials)} trials"

        server = Server(deployment["url"], deployment["instance"], workers=2, threads=4)
        with app.app_context():
            latest: dict[tuple[str, int], tuple[int, str]] = {}
            for name, fid, version, mask_digest in saves:
                if version >= latest.get((name, fid), (0, ""))[0]:
                    latest[(name, fid)] = (version, mask_digest)
            for (name, fid), (version, mask_digest) in latest.items():
                stored = db.session.execute(
                    db.select(Annotation).join(Annotation.author).where(Annotation.frame_id == fid).filter_by(username=name)
                ).scalar_one()
                # A save may commit and lose its answer in the kill, so the stored version can be newer.
                assert stored.version >= version, (name, fid)
                if stored.version == version:
                    assert digest(mask_of(stored)) == mask_digest, (name, fid)
            for code, trial_id in trials:
                trial = db.session.get(Trial, trial_id)
                assert trial.submitted_at is not None and len(trial.clicks) == 1, (code, trial_id)

            report = media.check()
            print(f"crash: {len(saves)} saves and {len(trials)} trials acknowledged before kill -9; "
                  f"{len(report.orphans)} orphaned media files found after restart")
            assert report.missing == []
            media.check(remove_orphans=True, grace_s=0)
            after = media.check()
            assert after.missing == [] and after.orphans == []

        # The restarted server works: the first annotator saves again on top of the last version.
        name, fid = next(iter(latest))
        with closing(staff_client(server.url, name, PASSWORD, timeout=10)) as client:
            current = client.get(f"/api/label/frames/{fid}/annotation").json()["version"]
            response = client.put(f"/api/label/frames/{fid}/annotation", json={"version": current, "instances": []})
        assert response.status_code == 200 and response.json()["version"] == current + 1
    finally:
        stop.set()
        server.stop()
