"""Any host serves anything, with real servers: two gunicorn "hosts" on one PostgreSQL database and one
SeaweedFS bucket, each with its own instance folder and cache (the second's empty). The second serves
the frames, masks and thumbnails the first stored, runs GrabCut and propagation on frames it has never
seen, and the two still meet the annotation's version check (409), not a lost write."""

import os
import uuid
from contextlib import closing

import numpy as np
import pytest
from flask_migrate import upgrade

from app import create_app
from app.extensions import db
from app.models import Frame
from app.services.users import create_user
from egonet import io
from tests.app.test_propagation import cup_at, iou, moving_frames
from tests.system.harness import Server, app_config, drop_schema, private_schema_url, rle, staff_client

POSTGRES_URL = os.environ.get("EGONET_TEST_POSTGRES_URL")
PASSWORD = "several-hosts-password"
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not POSTGRES_URL, reason="real servers run on PostgreSQL (EGONET_TEST_POSTGRES_URL)"),
]


@pytest.fixture
def two_hosts(tmp_path, seaweedfs):
    url, schema = private_schema_url(POSTGRES_URL)
    settings = {"STORAGE_URL": f"s3://egonet-test/{uuid.uuid4().hex[:12]}", "QUEUE_IN_PROCESS": "false"}
    first, second = tmp_path / "host-a", tmp_path / "host-b"
    app = create_app({**app_config(url, first), **settings}, instance_path=str(first))
    with app.app_context():
        upgrade()
        create_user("ann", "annotator", PASSWORD)
    frames = moving_frames(app)
    with app.app_context():
        paths = {f.id: (f.rgb_path, f.depth_path) for f in db.session.execute(db.select(Frame)).scalars()}
        db.session.remove()
        db.engine.dispose()
    second.mkdir()  # empty
    servers = []
    try:
        for instance in (first, second):
            servers.append(Server(url, instance, workers=2, threads=2, settings=settings))
        yield {"servers": servers, "frames": frames, "paths": paths, "second": second}
    finally:
        for server in servers:
            server.stop()
        drop_schema(POSTGRES_URL, schema)


def mask_of(client, url: str) -> np.ndarray:
    response = client.get(url)
    assert response.status_code == 200, response.text
    return io.decode_mask(response.content)


def test_a_second_host_serves_what_the_first_stored_and_edits_meet_the_version_check(two_hosts):
    (f0, f1, f2), paths = two_hosts["frames"], two_hosts["paths"]
    a, b = two_hosts["servers"]
    with closing(staff_client(a.url, "ann", PASSWORD, timeout=60)) as first, \
            closing(staff_client(b.url, "ann", PASSWORD, timeout=60)) as other:
        instances = [{"key": "k0", "kind": "tactile", "label": "cup", "mask": rle(cup_at(0))}]
        saved = first.put(f"/api/label/frames/{f0}/annotation", json={"version": 0, "instances": instances})
        assert saved.status_code == 200, saved.text

        # Frames, depth, masks and thumbnails the first host stored, from the second.
        rgb = other.get(f"/media/{paths[f0][0]}")
        assert rgb.status_code == 200 and rgb.content == first.get(f"/media/{paths[f0][0]}").content
        for url in (f"/frames/{f1}/thumb.jpg", f"/frames/{f2}/depth.png"):
            assert other.get(url).status_code == 200, url
        np.testing.assert_array_equal(mask_of(other, saved.json()["instances"][0]["mask_url"]), cup_at(0))

        # GrabCut on a frame no host has opened, propagation of the first host's work, on the second.
        box = other.post("/api/label/grabcut/box", json={"frame_id": f2, "instance": "k0", "box": [33, 35, 83, 85]},
                         headers={"Accept": "image/png"})
        assert box.status_code == 200, box.text
        assert iou(io.decode_mask(box.content), cup_at(2)) > 0.8
        carried = other.post(f"/api/label/frames/{f0}/propagate", json={})
        assert carried.status_code == 200, carried.text
        assert iou(mask_of(first, carried.json()["instances"][0]["mask_url"]), cup_at(1)) > 0.9
        cached = {p.relative_to(two_hosts["second"] / "cache" / "storage").as_posix()
                  for p in (two_hosts["second"] / "cache" / "storage").rglob("*") if p.is_file()}
        assert {f"media/{paths[f2][0]}", f"media/{paths[f2][1]}"} <= cached  # fetched from the bucket
        assert not (two_hosts["second"] / "media").exists()

        # Both hosts have version v of frame 1's annotation open; the second saves first.
        url = f"/api/label/frames/{f1}/annotation"
        version = first.get(url).json()["version"]
        assert other.get(url).json()["version"] == version
        edit = [{"key": "k0", "kind": "tactile", "label": "cup", "mask": rle(cup_at(1))}]
        assert other.put(url, json={"version": version, "instances": edit}).status_code == 200
        stale = first.put(url, json={"version": version, "instances": [{**edit[0], "label": "lost?"}]})
        assert stale.status_code == 409 and stale.json()["current_version"] == version + 1
        assert first.get(url).json()["instances"][0]["label"] == "cup"
