"""Any host serves anything: a second app server with an empty instance folder and cache, on the same
database, queue and STORAGE_URL (a SeaweedFS bucket, and a folder the hosts share), serves the frames,
masks, thumbnails and checkpoints the first one stored and runs GrabCut and propagation on frames it has
never seen; two hosts editing one annotation still meet the version check.
(tests/system/test_several_hosts.py does the same with two real servers.)"""


import numpy as np
import pytest
import torch

from app.extensions import db
from app.models import Frame
from app.services import media
from app.services import training

from egonet import io
from tests.app.conftest import make_app
from tests.app.test_labelling import get_png, rle
from tests.app.test_labelling_grabcut import call, forget_everything
from tests.app.test_propagation import annotate, cup_at, iou, moving_frames
from tests.app.test_training import hand_made_run

pytestmark = pytest.mark.both_storages


@pytest.fixture
def second_host(app, database_url, storage_url, tmp_path):
    """Another server: its own (empty) instance folder and CACHE_ROOT; the same database, queue and storage."""
    host = make_app(database_url, tmp_path / "host-b", STORAGE_URL=storage_url, QUEUE_URL=app.config["QUEUE_URL"])
    yield host
    with host.app_context():
        db.engine.dispose()


def files_under(folder) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()) if folder.exists() else []


def test_a_new_host_serves_frames_masks_thumbnails_and_runs_suggest_grabcut_and_propagation_on_them(
        app, second_host, storage_url, tmp_path, make_user, monkeypatch):
    f0, f1, f2 = moving_frames(app)
    user = make_user("annotator", "ann")
    first = app.test_client()
    first.login_as(user)
    saved = annotate(first, f0, cup_at(0))
    with app.app_context():
        frames = {f.id: (f.rgb_path, f.depth_path) for f in db.session.execute(db.select(Frame)).scalars()}
        rgb0 = media.read(frames[f0][0])
    host_b = tmp_path / "host-b"
    assert files_under(host_b / "cache") == [] and not (host_b / "instance" / "media").exists()

    other = second_host.test_client()
    other.login_as(user)
    forget_everything(second_host, monkeypatch)  # nothing of GrabCut's in memory: a new process
    with other.get(f"/media/{frames[f0][0]}") as response:
        assert response.status_code == 200 and response.data == rgb0
    with other.get(f"/frames/{f1}/thumb.jpg") as response:
        assert response.status_code == 200 and io.decode_image(response.data).shape[1] > 0
    with other.get(f"/frames/{f2}/depth.png") as response:
        assert response.status_code == 200
    np.testing.assert_array_equal(get_png(other, saved["instances"][0]["mask_url"]), cup_at(0))

    # Suggest (from depth) on a frame neither host has opened ...
    suggested = other.post(f"/api/label/frames/{f2}/suggest", json={"version": 0})
    assert suggested.status_code == 200, suggested.get_json()
    proposals = suggested.get_json()["annotation"]["instances"]
    assert proposals and max(iou(get_png(other, p["mask_url"]), cup_at(2)) for p in proposals) > 0.8
    # ... GrabCut (with the frame's depth) on it, and propagation from the first host's work.
    _, mask = call(other, "box", frame_id=f2, instance="k0", box=[33, 35, 83, 85])
    assert iou(mask, cup_at(2)) > 0.8
    carried = other.post(f"/api/label/frames/{f0}/propagate", json={})
    assert carried.status_code == 200, carried.get_json()
    assert iou(get_png(other, carried.get_json()["instances"][0]["mask_url"]), cup_at(1)) > 0.9
    # ... and what the second host made, the first serves.
    assert iou(get_png(first, carried.get_json()["instances"][0]["mask_url"]), cup_at(1)) > 0.9

    cached = files_under(host_b / "cache" / "storage")
    if storage_url.startswith("s3://"):  # the second host worked from copies of the bucket's objects
        assert f"media/{frames[f2][0]}" in cached and f"media/{frames[f2][1]}" in cached
        assert not (tmp_path / "instance" / "media").exists() and not (tmp_path / "media").exists()
    else:
        assert cached == []


def test_a_checkpoint_one_host_saves_another_serves_and_loads(app, second_host, make_user):
    with app.app_context():
        (checkpoint,) = hand_made_run(folds=("desk work",)).checkpoints
        checkpoint_id, key = checkpoint.id, checkpoint.path
    other = second_host.test_client()
    other.login_as(make_user("annotator"))
    url = f"/training/checkpoints/{checkpoint_id}/download"
    with other.get(url) as response:
        assert response.status_code == 200 and response.data == b"weights of desk work"
    with app.app_context():  # replaced on one host: the other serves the new file, not its old copy
        training.files.put(key, b"better weights")
    with other.get(url) as response:
        assert response.data == b"better weights"
    weights = {"fc.weight": torch.arange(12.0).reshape(3, 4)}
    with app.app_context():
        training.files.save(key, weights)
    with second_host.app_context():
        loaded = torch.load(training.files.local_path(key), map_location="cpu", weights_only=True)
    torch.testing.assert_close(loaded, weights)


def test_two_hosts_editing_one_annotation_get_a_version_conflict_not_a_lost_write(app, second_host, make_user):
    f0, *_ = moving_frames(app, 1)
    user = make_user("annotator", "ann")
    first, other = app.test_client(), second_host.test_client()
    first.login_as(user)
    other.login_as(user)
    url = f"/api/label/frames/{f0}/annotation"
    one = annotate(first, f0, cup_at(0))
    opened = other.get(url).get_json()
    assert opened["version"] == one["version"]
    both = [{"version": one["version"], "instances": [{"key": "k0", "kind": "tactile", "label": who,
                                                        "mask": rle(cup_at(n))}]}
            for n, who in ((1, "second host"), (2, "first host"))]
    assert other.put(url, json=both[0]).status_code == 200
    stale = first.put(url, json=both[1])  # from the version both hosts had open
    assert stale.status_code == 409 and stale.get_json()["current_version"] == one["version"] + 1
    kept = first.get(url).get_json()
    assert kept["instances"][0]["label"] == "second host"
    np.testing.assert_array_equal(get_png(first, kept["instances"][0]["mask_url"]), cup_at(1))
