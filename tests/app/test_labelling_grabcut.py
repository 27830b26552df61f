"""GrabCut on the server: box, strokes, undo, bad input, and sessions that
survive a restart, several workers and concurrent strokes."""

import threading

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame
from app.models.annotations import GrabCutState
from app.services.labelling import grabcut as grabcut_service
from egonet import io
from tests.app.test_labelling import H, W, body, make_frames, square, true_mask

BOX = [40, 25, 125, 95]


@pytest.fixture
def annotator(client, make_user):
    client.login_as(make_user("annotator", "ann"))
    return client


def forget_everything(app, monkeypatch):
    """Every request from now on as if served by a new worker process: nothing kept in memory."""
    monkeypatch.setattr(grabcut_service, "_sessions", grabcut_service._Recent())
    monkeypatch.setattr(grabcut_service, "_frames", grabcut_service._Recent())
    monkeypatch.setitem(app.config, "GRABCUT_CACHE_BYTES", 0)
    monkeypatch.setitem(app.config, "GRABCUT_IMAGE_CACHE_BYTES", 0)


@pytest.fixture
def fresh_workers(app, monkeypatch):
    forget_everything(app, monkeypatch)


def call(client, op: str, **body):
    with client.post(f"/api/label/grabcut/{op}", json=body) as response:
        if response.status_code != 200:
            return response.status_code, response.get_json()
        assert response.mimetype == "image/png" and response.headers["Cache-Control"] == "no-store"
        return response.headers["X-Can-Undo"], io.decode_mask(response.data)


def iou(a, b):
    return (a & b).sum() / max(1, (a | b).sum())


@pytest.mark.both_storages
def test_box_stroke_undo(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    can_undo, boxed = call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    assert can_undo == "1" and boxed.shape == (H, W)
    assert iou(boxed, true_mask()) > 0.9

    # A background stroke through the object's middle: those pixels are out, exactly.
    _, stroked = call(annotator, "stroke", frame_id=frame_id, instance="a", points=[[60, 60], [100, 60]], label="bg", radius=3)
    assert not stroked[57:64, 60:101].any()
    assert stroked[45, 80] and boxed[60, 80]
    _, undone = call(annotator, "undo", frame_id=frame_id, instance="a")
    assert np.array_equal(undone, boxed)
    with annotator.get(f"/api/label/grabcut/mask.png?frame_id={frame_id}&instance=a") as response:
        assert np.array_equal(io.decode_mask(response.data), boxed)

    # The session belongs to the user, frame and object key.
    assert annotator.get(f"/api/label/frames/{frame_id}/annotation").get_json()["grabcut"] == ["a"]
    with annotator.get(f"/api/label/grabcut/mask.png?frame_id={frame_id}&instance=b") as response:
        assert response.status_code == 404
    status, error = call(annotator, "stroke", frame_id=frame_id, instance="b", points=[[60, 60]], label="fg", radius=3)
    assert status == 400 and "box" in error["fields"]

    # Undo past the box, then once more: nothing left.
    _, empty = call(annotator, "undo", frame_id=frame_id, instance="a")
    assert not empty.any()
    status, error = call(annotator, "undo", frame_id=frame_id, instance="a")
    assert status == 409


BAD_INPUT = [
    ("box", {"box": [10, 10, 10, 50]}, "box"),  # empty
    ("box", {"box": [-5, 10, 50, 50]}, "box"),  # outside
    ("box", {"box": [10, 10, W + 1, 50]}, "box"),
    ("box", {"box": [0, 0, W, H]}, "box"),  # the whole frame
    ("box", {"box": [1, 2, 3]}, "box"),
    ("box", {"box": "all"}, "box"),
    ("box", {"frame_id": 9999}, "frame_id"),  # unknown frame
    ("box", {"frame_id": "one"}, "frame_id"),
    ("box", {"instance": "a b"}, "instance"),
    ("box", {"instance": ""}, "instance"),
    ("stroke", {"points": []}, "points"),  # no points
    ("stroke", {"points": [[1]]}, "points[0]"),
    ("stroke", {"points": [[1, "x"]]}, "points[0][1]"),
    ("stroke", {"points": [[-100, -100]]}, "points"),
    ("stroke", {"points": [[-500, -500]]}, "points[0]"),
    ("stroke", {"points": [[60, 60], [1e308, 60]]}, "points[1]"),
    ("stroke", {"radius": 1e308}, "radius"),
    ("stroke", {"radius": 0}, "radius"),
    ("stroke", {"radius": -2}, "radius"),
    ("stroke", {"label": "maybe"}, "label"),
    ("stroke", {"frame_id": 9999}, "frame_id"),
    ("undo", {"frame_id": 9999}, "frame_id"),
]


def test_bad_grabcut_input_is_400_naming_the_field(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    call(annotator, "box", frame_id=frame_id, instance="a", box=BOX)
    for op, change, field in BAD_INPUT:
        request = {"frame_id": frame_id, "instance": "a"}
        if op == "box":
            request["box"] = BOX
        if op == "stroke":
            request.update(points=[[60, 60]], label="fg", radius=3)
        request.update(change)
        status, error = call(annotator, op, **request)
        assert status == 400, (op, change, error)
        assert field in error["fields"], (op, change, error)


def test_mask_query_is_checked(app, annotator):
    frame_id, *_ = make_frames(app, n=1)
    for query, field in (("", "frame_id"), ("?frame_id=9999&instance=a", "frame_id"), (f"?frame_id={frame_id}", "instance")):
        with annotator.get(f"/api/label/grabcut/mask.png{query}") as response:
            assert response.status_code == 400 and field in response.get_json()["fields"]


@pytest.mark.both_storages
def test_a_session_survives_a_restart_and_other_workers(app, annotator, monkeypatch):
    """The same operations with and without sessions kept in memory give the same masks."""
    frame_id, *_ = make_frames(app, n=1)
    steps = [
        ("box", {"box": BOX}),
        ("stroke", {"points": [[60, 60], [100, 62]], "label": "bg", "radius": 3}),
        ("stroke", {"points": [[45, 30], [48, 33]], "label": "fg", "radius": 2}),
        ("undo", {}),
        ("stroke", {"points": [[120, 50]], "label": "bg", "radius": 4}),
    ]

    def run(instance):
        return [call(annotator, op, frame_id=frame_id, instance=instance, **args)[1] for op, args in steps]

    in_memory = run("warm")
    forget_everything(app, monkeypatch)
    restarted = run("cold")
    for a, b in zip(in_memory, restarted):
        assert np.array_equal(a, b)
    # A restored session goes on where it stopped, undo levels included.
    _, back = call(annotator, "undo", frame_id=frame_id, instance="cold")
    assert np.array_equal(back, in_memory[3])


def test_concurrent_strokes_do_not_interleave(app, make_user, fresh_workers):
    frame_id, *_ = make_frames(app, n=1)
    user = make_user("annotator", "ann")
    clients = [app.test_client() for _ in range(4)]
    for c in clients:
        c.login_as(user)
    _, boxed = call(clients[0], "box", frame_id=frame_id, instance="a", box=BOX)
    strokes = [[[55 + 10 * i, 60]] for i in range(4)]
    results = [None] * 4

    def stroke(i):
        results[i] = call(clients[i], "stroke", frame_id=frame_id, instance="a", points=strokes[i], label="bg", radius=2)

    threads = [threading.Thread(target=stroke, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(r[0] == "1" for r in results), [r[0] for r in results]
    # Every stroke landed on its own undo level: four undos lead back to the box's mask.
    with clients[0].get(f"/api/label/grabcut/mask.png?frame_id={frame_id}&instance=a") as final:
        final_mask = io.decode_mask(final.data)
    for x in (55, 65, 75, 85):
        assert not final_mask[60, x]
    for _ in range(4):
        _, mask = call(clients[0], "undo", frame_id=frame_id, instance="a")
    assert np.array_equal(mask, boxed)


def test_sessions_end_with_their_objects(app, annotator, make_user):
    frame_id, *_ = make_frames(app, n=1)
    for key in ("a", "b"):
        call(annotator, "box", frame_id=frame_id, instance=key, box=BOX)
    url = f"/api/label/frames/{frame_id}/annotation"
    request = body(0, square(30, 80, 50, 110), status="done")
    request["instances"][0]["key"] = "a"
    done = annotator.put(url, json=request).get_json()
    # Marked done: the session of the object that was deleted ("b") goes.
    assert annotator.get(url).get_json()["grabcut"] == ["a"]
    reviewer = app.test_client()
    reviewer.login_as(make_user("reviewer", "rev"))
    reviewer.post(f"/api/label/annotations/{done['id']}/review", json={"version": done["version"], "decision": "accept"})
    with app.app_context():
        assert db.session.execute(db.select(GrabCutState)).scalars().all() == []


def test_workers_share_decoded_frames_on_disk_within_a_budget(app, annotator, monkeypatch):
    frame_ids = make_frames(app, n=3)
    forget_everything(app, monkeypatch)  # every request as if in a new worker
    folder = grabcut_service.Path(app.config["CACHE_ROOT"]) / "grabcut-frames"
    call(annotator, "box", frame_id=frame_ids[0], instance="a", box=BOX)
    (copy,) = [p for p in folder.glob("*.npy") if "-" not in p.stem]  # beside it: the guides, "<frame>-v1-..."
    with app.app_context():
        frame = db.session.get(Frame, frame_ids[0])
        assert np.array_equal(np.load(copy), io.read_image(grabcut_service.media.local_path(frame.rgb_path)))

    # A worker that has not seen the frame loads the shared copy: no decoding.
    def no_decoding(*args, **kwargs):
        raise AssertionError("decoded the frame again")

    monkeypatch.setattr(grabcut_service.egonet_io, "read_image", no_decoding)
    status, mask = call(annotator, "stroke", frame_id=frame_ids[0], instance="a", points=[[60, 60]], label="bg", radius=3)
    assert status == "1" and not mask[60, 60]
    monkeypatch.undo()
    forget_everything(app, monkeypatch)

    # The copies stay within GRABCUT_DISK_CACHE_BYTES: the least recently used go first.
    copy_size = copy.stat().st_size
    monkeypatch.setitem(app.config, "GRABCUT_DISK_CACHE_BYTES", int(1.5 * copy_size))
    call(annotator, "box", frame_id=frame_ids[1], instance="a", box=BOX)
    call(annotator, "box", frame_id=frame_ids[2], instance="a", box=BOX)
    assert sum(p.stat().st_size for p in folder.glob("*.npy")) <= 1.5 * copy_size and not copy.exists()


def test_the_app_runs_numpy_blas_and_opencv_on_one_thread_unless_told(tmp_path):
    """COMPUTE_THREADS: 1 by default (a request's GrabCut runs on one core), any other number when set."""
    import cv2
    import threadpoolctl

    from app import create_app

    def threads():
        blas = {lib["num_threads"] for lib in threadpoolctl.threadpool_info() if lib["user_api"] == "blas"}
        return blas, cv2.getNumThreads()

    before = threadpoolctl.threadpool_limits(limits=2, user_api="blas")  # restored at the end
    opencv_before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    try:
        create_app({"TESTING": True, "SECRET_KEY": "x" * 32}, instance_path=str(tmp_path / "a"))
        assert threads() == ({1}, 1)
        create_app({"TESTING": True, "SECRET_KEY": "x" * 32, "COMPUTE_THREADS": 2}, instance_path=str(tmp_path / "b"))
        assert threads() == ({2}, 2)
        cv2.setNumThreads(3)
        create_app({"TESTING": True, "SECRET_KEY": "x" * 32, "COMPUTE_THREADS": None}, instance_path=str(tmp_path / "c"))
        assert threads() == ({2}, 3)  # left as they were
    finally:
        before.restore_original_limits()
        cv2.setNumThreads(opencv_before)


def test_a_served_app_freezes_its_start_up_objects_out_of_the_garbage_collector(tmp_path):
    """Outside tests, create_app ends with gc.freeze(): a full collection then scans only what
    requests made, not the ~150k objects of the start-up (85-105 ms each time otherwise)."""
    import subprocess
    import sys

    script = (
        "import gc, sys; from app import create_app; "
        "testing = sys.argv[1] == 'testing'; "
        "create_app({'TESTING': testing, 'SECRET_KEY': 'x' * 32}, instance_path=sys.argv[2]); "
        "print(gc.get_freeze_count())"
    )
    counts = {}
    for mode in ("served", "testing"):
        done = subprocess.run([sys.executable, "-c", script, mode, str(tmp_path / mode)], capture_output=True,
                              text=True, check=True, timeout=120)
        counts[mode] = int(done.stdout.split()[-1])
    assert counts["served"] > 50_000 and counts["testing"] == 0
