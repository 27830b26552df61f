"""Export (every annotation: PNG per frame and annotator, COCO JSON with RLE, images) and import back:
a round trip is exact; filters, "nothing matches", and exports built by the worker."""

import io as bytes_io
import json
import os
import stat
import subprocess
import sys
import time
import uuid
import warnings
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pycocotools.mask as coco_mask
import pytest
from pycocotools.coco import COCO

from app.extensions import db
from app.models import Annotation, Frame, Instance, Role, Status, User
from app.models.exports import ExportJob, ExportStatus
from app.services import exchange, labelling, media
from app.services.importing import import_path
from app.services.storage import store as storage
from app.services.users import create_user
from egonet import io
from tests.app.factories import image_folder, rgb_image

SIZE = (48, 64)
ROOT = Path(__file__).resolve().parents[2]


def recording(root: Path) -> Path:
    """Four PNG frames plus a JPEG that shares a stem with one of them."""
    folder = image_folder(root, n=4, size=SIZE)
    ok, jpeg = cv2.imencode(".jpg", rgb_image(99, SIZE))
    (folder / "rgb" / "00001.jpg").write_bytes(jpeg.tobytes())
    return folder


def blob(y0, y1, x0, x1) -> np.ndarray:
    mask = np.zeros(SIZE, bool)
    mask[y0:y1, x0:x1] = True
    return mask


def save(frame, user, *masks, status="done", kinds=None, no_action_object=False, seconds=0.0):
    kinds = kinds or [None] * len(masks)
    body = {
        "version": 0,
        "instances": [
            {"key": f"k{i}", "kind": kind, "label": "cup" if kind == "tactile" else None, "mask": _rle(m)}
            for i, (m, kind) in enumerate(zip(masks, kinds))
        ],
        "no_action_object": no_action_object,
        "status": status,
        "time_spent_delta_s": seconds,
    }
    return labelling.save_annotation(frame, user, body)


def _rle(mask):
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in encoded["size"]], "counts": encoded["counts"].decode()}


# Frame 0 has ann's done annotation and bob's reviewed one (bob's is the frame's mask); frame 4 two done
# ones (bob's, the later, is the frame's mask); frame 3 is only in progress (not exported by default).
ANN_0 = [blob(2, 20, 3, 30), blob(25, 40, 35, 60)]
BOB_0 = [blob(5, 25, 5, 40)]
ANN_2 = [blob(10, 30, 10, 50)]
ANN_4, BOB_4 = [blob(30, 48, 0, 64)], [blob(28, 48, 10, 64)]


def labelled_dataset(app, folder: Path) -> dict[str, dict[str, list[np.ndarray]]]:
    """Frames with every kind of annotation; returns {frame name: {annotator: instance masks}}, exported by default."""
    with app.app_context():
        import_path(folder, activity="cooking")
        frames = db.session.execute(db.select(Frame).order_by(Frame.index, Frame.source_name, Frame.id)).scalars().all()
        ann, _ = create_user("ann", Role.ANNOTATOR, "ann-password")
        bob, _ = create_user("bob", Role.ANNOTATOR, "bob-password")
        rev, _ = create_user("rev", Role.REVIEWER, "rev-password")
        save(frames[0], ann, *ANN_0, kinds=["tactile", "visual"], seconds=41.25)
        accepted = save(frames[0], bob, *BOB_0, kinds=["visual"])
        labelling.review_annotation(accepted, rev, version=accepted.version, decision="accept", comment="Nice.")
        save(frames[1], ann, no_action_object=True)
        accepted = save(frames[2], ann, *ANN_2, seconds=3)
        labelling.review_annotation(accepted, rev, version=accepted.version, decision="accept", comment="Good.")
        save(frames[3], ann, blob(0, 5, 0, 5), status=None)  # in progress: not exported by default
        save(frames[4], ann, *ANN_4)
        save(frames[4], bob, *BOB_4)
        return {
            "cooking/rec/00000": {"bob": BOB_0, "ann": ANN_0},
            f"cooking/rec/{_stem(frames[1])}": {"ann": []},
            f"cooking/rec/{_stem(frames[2])}": {"ann": ANN_2},
            f"cooking/rec/{_stem(frames[4])}": {"bob": BOB_4, "ann": ANN_4},
        }


def _stem(frame: Frame) -> str:
    return frame.source_name if frame.source_name != "00001" else f"00001~{frame.content_hash[:12]}"


def union(masks) -> np.ndarray:
    return np.logical_or.reduce(masks) if masks else np.zeros(SIZE, bool)


def wipe(app) -> None:
    """An empty database: no frames, users or annotations (media files stay, as on a new server)."""
    with app.app_context():
        with db.engine.begin() as conn:
            for table in reversed(db.metadata.sorted_tables):
                conn.execute(table.delete())


def files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def zipped(data: bytes) -> dict[str, bytes]:
    archive = zipfile.ZipFile(bytes_io.BytesIO(data))
    return {name: archive.read(name) for name in archive.namelist()}


@pytest.mark.both_storages
def test_every_annotation_is_exported_and_the_round_trip_is_bit_for_bit(app, runner, tmp_path):
    folder = recording(tmp_path / "rec")
    expected = labelled_dataset(app, folder)
    first, second = tmp_path / "first", tmp_path / "second"
    result = runner.invoke(args=["egonet", "export", "--out", str(first)])
    assert result.exit_code == 0, result.output
    assert "4 frames, 6 annotations, 6 action-objects exported" in result.output

    exported = files(first)
    layout = {"annotations.json"} | {f"masks/{name}.png" for name in expected}
    layout |= {f"annotators/{who}/{name}.png" for name, by in expected.items() for who in by}
    assert set(exported) == layout
    for name, by in expected.items():
        for who, masks in by.items():
            assert np.array_equal(io.decode_mask(exported[f"annotators/{who}/{name}.png"]), union(masks)), (name, who)
        # The frame's mask is its best annotation's: bob's reviewed one on frame 0, bob's later done one on frame 4.
        assert exported[f"masks/{name}.png"] == exported[f"annotators/{next(iter(by))}/{name}.png"]
        assert set(np.unique(cv2.imdecode(np.frombuffer(exported[f"masks/{name}.png"], np.uint8), -1))) <= {0, 255}

    wipe(app)
    with app.app_context():
        import_path(folder, activity="cooking")
    result = runner.invoke(args=["egonet", "import-annotations", str(first)])
    assert result.exit_code == 0, result.output
    assert "6 annotations (6 action-objects) imported" in result.output
    result = runner.invoke(args=["egonet", "export", "--out", str(second)])
    assert result.exit_code == 0, result.output
    assert files(second) == exported

    with app.app_context():
        reviewed = db.session.execute(db.select(Annotation).filter_by(status=Status.REVIEWED)).scalars().all()
        assert sorted((a.author.username, a.review_comment, a.reviewer.username) for a in reviewed) == [
            ("ann", "Good.", "rev"), ("bob", "Nice.", "rev")]
        author = db.session.execute(db.select(User).filter_by(username="ann")).scalar_one()
        assert not author.active and author.password_hash is None  # created by the import, cannot sign in


def test_an_export_into_a_bucket_holds_what_a_folder_would(app, runner, tmp_path, seaweedfs):
    labelled_dataset(app, recording(tmp_path / "rec"))
    assert runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "folder"), "--images"]).exit_code == 0
    url = f"s3://egonet-test/exports-{uuid.uuid4().hex[:8]}/labels/"
    result = runner.invoke(args=["egonet", "export", "--out", url, "--images"])
    assert result.exit_code == 0 and f"{url}: 4 frames" in result.output, result.output
    prefix = url.removeprefix("s3://egonet-test/")
    client = seaweedfs.client()
    listed = client.list_objects_v2(Bucket="egonet-test", Prefix=prefix)["Contents"]
    in_bucket = {o["Key"][len(prefix):]: client.get_object(Bucket="egonet-test", Key=o["Key"])["Body"].read() for o in listed}
    assert in_bucket == files(tmp_path / "folder")

    result = runner.invoke(args=["egonet", "export", "--out", url])
    assert result.exit_code == 1 and "holds files already" in result.output and result.output.count("\n") == 1

    with app.app_context():  # a frame's file lost half-way: what was written goes again
        last = db.session.execute(db.select(Frame).order_by(Frame.index.desc())).scalars().first()
        storage().delete(f"media/{last.rgb_path}")
    result = runner.invoke(args=["egonet", "export", "--out", url.replace("labels", "never"), "--images"])
    assert result.exit_code == 1 and isinstance(result.exception, FileNotFoundError)
    assert "Contents" not in client.list_objects_v2(Bucket="egonet-test", Prefix=prefix.replace("labels", "never"))


def test_coco_has_one_entry_per_instance_with_its_annotator_and_status(app, runner, tmp_path):
    expected = labelled_dataset(app, recording(tmp_path / "rec"))
    assert runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "out"), "--format", "coco"]).exit_code == 0
    assert sorted(files(tmp_path / "out")) == ["annotations.json"]
    coco = COCO(str(tmp_path / "out" / "annotations.json"))

    def decoded(annotation):
        with warnings.catch_warnings():  # pycocotools' Cython code predates numpy 2's __array__ copy keyword
            warnings.simplefilter("ignore", DeprecationWarning)
            return coco.annToMask(annotation).astype(bool)

    assert len(coco.getImgIds()) == 4 and coco.loadCats(1)[0]["name"] == "action-object"
    for image in coco.loadImgs(coco.getImgIds()):
        by = expected[image["file_name"].rsplit(".", 1)[0]]
        entries = coco.loadAnns(coco.getAnnIds(imgIds=image["id"]))
        assert [e["attributes"]["annotator"] for e in entries] == [w for w, masks in by.items() for _ in masks]
        for entry, mask in zip(entries, [m for masks in by.values() for m in masks]):
            assert np.array_equal(decoded(entry), mask) and entry["area"] == mask.sum()
        records = image["egonet"]["annotations"]
        assert [r["annotator"] for r in records] == list(by) and [r["frame_mask"] for r in records] == [True] + [False] * (len(by) - 1)
        assert "mask_file" not in image["egonet"] and all("mask_file" not in r for r in records)  # no PNGs written
    first = coco.loadImgs(1)[0]["egonet"]["annotations"]
    assert [(r["annotator"], r["status"], r["time_spent_s"], r["reviewer"]) for r in first] == [
        ("bob", "reviewed", 0.0, "rev"), ("ann", "done", 41.25, None)]
    assert [(e["attributes"]["kind"], e["attributes"]["status"]) for e in coco.loadAnns(coco.getAnnIds(imgIds=1))] == [
        ("visual", "reviewed"), ("tactile", "done"), ("visual", "done")]
    assert coco.loadImgs(2)[0]["egonet"]["annotations"][0]["no_action_object"] is True


def test_png_masks_alone_round_trip(app, runner, tmp_path):
    folder = recording(tmp_path / "rec")
    labelled_dataset(app, folder)
    assert runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "a"), "--format", "png"]).exit_code == 0
    wipe(app)
    with app.app_context():
        import_path(folder, activity="cooking")
    result = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a")])
    assert result.exit_code == 0, result.output
    assert "6 annotations (5 action-objects) imported" in result.output  # a PNG holds an annotation's union
    assert runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "b"), "--format", "png"]).exit_code == 0
    assert files(tmp_path / "b") == files(tmp_path / "a")  # masks/ picks the same annotation again
    with app.app_context():
        annotations = db.session.execute(db.select(Annotation)).scalars().all()
        assert {a.status for a in annotations} == {Status.DONE}  # PNGs record no status
        assert sum(a.no_action_object for a in annotations) == 1
    # Importing again keeps what is there, unless asked to replace it.
    again = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a")])
    assert "0 annotations (0 action-objects) imported, 6 kept as they were" in again.output
    replaced = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a"), "--replace"])
    assert "6 annotations" in replaced.output
    # One author for everything only where each frame has one annotation: masks/ alone (another tool's layout).
    many = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a"), "--author", "wearer"])
    assert many.exit_code != 0 and "a second annotation of this frame by 'wearer'" in many.output
    assert many.output.strip().count("\n") == 0
    only = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a" / "masks"), "--author", "wearer"])
    assert only.exit_code == 0 and "4 annotations" in only.output, only.output


def test_filters_images_and_nothing_to_export_on_the_command_line(app, runner, tmp_path):
    labelled_dataset(app, recording(tmp_path / "rec"))
    bob = tmp_path / "bob"
    result = runner.invoke(args=["egonet", "export", "--out", str(bob), "--annotator", "bob", "--images",
                                 "--format", "png"])
    assert result.exit_code == 0, result.output
    assert "2 frames, 2 annotations, 2 action-objects, 2 images exported" in result.output
    with app.app_context():
        frame = db.session.execute(db.select(Frame).filter_by(source_name="00000")).scalar_one()
        rgb = media.read(frame.rgb_path)
    images = sorted(p for p in files(bob) if p.startswith("images/"))
    assert len(images) == 2 and files(bob)["images/cooking/rec/00000.png"] == rgb  # the stored file, byte for byte
    assert not any(p.startswith("annotators/ann") for p in files(bob))

    progress = runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "p"), "--status", "in_progress",
                                   "--activity", "cooking"])
    assert progress.exit_code == 0 and "1 frames, 1 annotations" in progress.output, progress.output

    def fails(*args, expect):
        out = tmp_path / "never"
        result = runner.invoke(args=["egonet", "export", "--out", str(out), *args])
        assert result.exit_code != 0, result.output
        assert result.output.startswith("Error: ") and result.output.strip().count("\n") == 0, result.output
        assert expect in result.output, result.output
        assert not out.exists() and not list(tmp_path.glob(".never*"))

    fails("--status", "rejected", expect="nothing to export: no annotation is rejected (there are 2 reviewed, "
                                         "4 done, 1 in progress: choose those statuses)")
    fails("--annotator", "bob", "--status", "in_progress", expect="no annotation is in progress by bob (there are 1 "
                                                                 "reviewed, 1 done")
    fails("--annotator", "carol", expect="--annotator: no user named 'carol'")
    fails("--activity", "gardening", expect="--activity: no activity named 'gardening'")


def test_version_1_coco_files_still_import(app, runner, tmp_path):
    """One annotation per image, its author and status on the image (the exports before issue 15)."""
    folder = recording(tmp_path / "rec")
    with app.app_context():
        import_path(folder, activity="cooking")
        frame = db.session.execute(db.select(Frame).filter_by(source_name="00000")).scalar_one()
        digest = frame.content_hash
    coco = {
        "images": [{"id": 7, "file_name": "cooking/rec/00000.png", "width": 64, "height": 48,
                    "egonet": {"content_hash": digest, "author": "old", "status": "reviewed", "time_spent_s": 5.0}}],
        "annotations": [{"id": 1, "image_id": 7, "segmentation": _rle(ANN_2[0]), "egonet": {"kind": "tactile"}}],
    }
    (tmp_path / "v1.json").write_text(json.dumps(coco))
    result = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "v1.json")])
    assert result.exit_code == 0 and "1 annotations (1 action-objects)" in result.output, result.output
    with app.app_context():
        (annotation,) = db.session.execute(db.select(Annotation)).scalars().all()
        assert (annotation.author.username, annotation.status, annotation.time_spent_s) == ("old", Status.REVIEWED, 5.0)
        assert annotation.instances[0].kind.value == "tactile"


def test_the_page_downloads_small_exports_and_says_when_nothing_matches(app, admin_client, tmp_path):
    labelled_dataset(app, recording(tmp_path / "rec"))
    form = {"format": "both", "status": ["in_progress", "done"], "annotator": ["ann"]}
    with admin_client.post("/label/exports", data=form) as response:
        assert response.status_code == 200 and response.mimetype == "application/zip"
        assert response.headers["X-Exported-Frames"] == "4"  # ann's done frames and the one in progress
        names = set(zipped(response.data))
    assert {"annotations.json", "masks/cooking/rec/00003.png", "annotators/ann/cooking/rec/00003.png"} <= names
    assert not any(n.startswith("annotators/bob") for n in names)

    response = admin_client.post("/label/exports", data={"status": "rejected", "activity": "cooking"})
    assert response.status_code == 302 and response.mimetype != "application/zip"
    assert response.location.endswith("/label/?status=rejected&activity=cooking#export")
    page = admin_client.get(response.location).get_data(as_text=True)
    assert 'id="export-message"' in page and "Nothing to export: no annotation is rejected in cooking" in page
    assert 'value="rejected" checked' in page and 'value="cooking" checked' in page  # the choices are kept
    assert page.count("Nothing to export") == 1  # in the export card, not at the top as well
    for form, expect in (({"status": "lost"}, "Status: &#39;lost&#39; is not a valid Status"),
                         ({}, "Status: choose at least one status"),
                         ({"status": "done", "format": "tiff"}, "Format must be one of png, coco, both")):
        page = admin_client.post("/label/exports", data=form, follow_redirects=True).get_data(as_text=True)
        assert expect in page, (form, page[page.find("export-message"):][:300])

    path = tmp_path / "download.zip"
    with admin_client.post("/label/exports", data={"status": ["done", "reviewed"]}) as response:
        path.write_bytes(response.data)
    with app.app_context():
        db.session.execute(db.delete(Instance))
        db.session.execute(db.delete(Annotation))
        db.session.commit()
        report = exchange.import_annotations(path)
        assert (report.annotations, report.instances) == (6, 6)


@pytest.mark.both_storages
def test_large_exports_are_built_by_the_worker_with_progress(app, app_with, admin_client, make_user, tmp_path):
    labelled_dataset(app, recording(tmp_path / "rec"))
    form = {"format": "both", "status": ["done", "reviewed"]}
    with admin_client.post("/label/exports", data=form) as response:
        small = response.data
    response = admin_client.post("/label/exports", data=form | {"images": "1"})  # images: never in the request
    assert response.status_code == 302 and "/label/exports/" in response.location
    export_id = int(response.location.rsplit("/", 1)[1])
    state = admin_client.get(f"/api/label/exports/{export_id}").get_json()
    assert (state["status"], state["done"], state["total"], state["download_url"]) == ("queued", 0, 4, None)
    page = admin_client.get(response.location).get_data(as_text=True)
    assert "Queued: the queue's worker builds it" in page and "with the frames' images" in page
    assert admin_client.get(f"/label/exports/{export_id}/download").status_code == 409

    app.config["EXPORT_MAX_PENDING"] = 1
    page = admin_client.post("/label/exports", data=form | {"images": "1"}, follow_redirects=True).get_data(as_text=True)
    assert "You have 1 exports waiting or under way (at most 1)" in page

    with app.app_context():
        job = exchange.build_export(export_id)  # what the worker runs
        assert (job.status, job.done, job.total, job.annotations, job.instances) == (ExportStatus.DONE, 4, 4, 6, 6)
        assert exchange.build_export(export_id).finished_at == job.finished_at  # a finished job is left alone
    state = admin_client.get(f"/api/label/exports/{export_id}").get_json()
    assert state["status"] == "done" and state["download_url"] == f"/label/exports/{export_id}/download"
    with admin_client.get(state["download_url"]) as download:
        assert download.status_code == 200 and download.mimetype == "application/zip"
        built = zipped(download.data)
    assert {n: d for n, d in built.items() if not n.startswith("images/")} == zipped(small)
    assert len([n for n in built if n.startswith("images/")]) == 4

    # Another staff member sees it listed, and may fetch it from another host (its own empty cache).
    other = app_with(STORAGE_URL=app.config["STORAGE_URL"], CACHE_ROOT=str(tmp_path / "host-2")).test_client()
    other.login_as(make_user("reviewer", "viewer"))
    assert f'href="/label/exports/{export_id}/download"' in other.get("/label/").get_data(as_text=True)
    with other.get(f"/label/exports/{export_id}/download") as download:
        assert download.status_code == 200

    # Only the EXPORT_KEEP most recent finished exports are kept, files too.
    app.config.update(EXPORT_KEEP=0, EXPORT_MAX_PENDING=5)
    with app.app_context():
        assert storage().exists(f"exports/export-{export_id}.zip")
        admin_client.post("/label/exports", data=form | {"images": "1"})
        assert not storage().exists(f"exports/export-{export_id}.zip")
    assert admin_client.get(f"/api/label/exports/{export_id}").status_code == 404


def test_a_failed_export_says_why(app, tmp_path):
    labelled_dataset(app, recording(tmp_path / "rec"))
    with app.app_context():
        user = db.session.execute(db.select(User).filter_by(username="ann")).scalar_one()
        job = ExportJob(requested_by=user, options=exchange.ExportOptions.of(annotators=["ann"]).to_dict(), total=4)
        db.session.add(job)
        db.session.commit()
        db.session.execute(db.delete(Instance))
        db.session.execute(db.delete(Annotation))
        db.session.commit()
        with pytest.raises(exchange.NothingToExport):
            exchange.build_export(job.id)
        db.session.expire_all()
        failed = db.session.get(ExportJob, job.id)
        assert failed.status is ExportStatus.FAILED and failed.message.startswith("nothing to export")
        assert not list(storage().list("exports"))  # no partial zip left behind


@pytest.mark.slow
def test_a_queued_export_is_built_by_a_real_worker(app, database_url, admin_client, tmp_path):
    labelled_dataset(app, recording(tmp_path / "rec"))
    response = admin_client.post("/label/exports", data={"status": ["done", "reviewed"], "images": "1"})
    export_id = int(response.location.rsplit("/", 1)[1])
    env = dict(
        os.environ,
        EGONET_QUEUE_URL=app.config["QUEUE_URL"],
        FLASK_SQLALCHEMY_DATABASE_URI=database_url,
        FLASK_SECRET_KEY="worker-test-secret-key-0123456789abcdef",
        FLASK_STORAGE_URL=str(tmp_path),
        FLASK_CACHE_ROOT=str(tmp_path / "cache"),
        OMP_NUM_THREADS="1",
    )
    worker = subprocess.Popen([sys.executable, "-m", "flask", "--app", "app", "egonet", "worker"], cwd=ROOT, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            state = admin_client.get(f"/api/label/exports/{export_id}").get_json()
            if state["status"] in ("done", "failed"):
                break
            time.sleep(0.2)
    finally:
        worker.terminate()
        out = worker.communicate(timeout=20)[0]
    assert state["status"] == "done", out[-3000:]
    with admin_client.get(state["download_url"]) as download:
        assert len([n for n in zipped(download.data) if n.startswith("images/")]) == 4


def test_export_and_import_problems_are_one_line(app, runner, tmp_path):
    folder = recording(tmp_path / "rec")
    labelled_dataset(app, folder)
    out = tmp_path / "out"
    assert runner.invoke(args=["egonet", "export", "--out", str(out)]).exit_code == 0

    def fails(*args, expect):
        result = runner.invoke(args=["egonet", *args])
        assert result.exit_code != 0, result.output
        assert expect in result.output and result.output.strip().count("\n") == 0, result.output

    fails("export", "--out", str(out), expect="not an empty folder")
    fails("import-annotations", str(tmp_path / "nothing"), expect="no such file or folder")
    fails("import-annotations", str(out), "--author", "wearer", expect="2 annotators' annotations of one frame")

    # Frames that are not in the database stop the import, or are skipped when asked.
    wipe(app)
    fails("import-annotations", str(out), expect="no matching frame")
    fails("import-annotations", str(out / "masks"), expect="no frame 'cooking/rec/00000'")
    result = runner.invoke(args=["egonet", "import-annotations", str(out), "--skip-missing"])
    assert result.exit_code == 0 and "4 without a frame skipped" in result.output

    with app.app_context():
        import_path(folder, activity="cooking")
    bad = tmp_path / "bad"
    (bad / "masks" / "cooking" / "rec").mkdir(parents=True)
    (bad / "masks" / "cooking" / "rec" / "00000.png").write_bytes(io.encode_png(np.zeros((5, 5), bool)))
    fails("import-annotations", str(bad), expect="does not match the frame's 64x48")
    (bad / "annotations.json").write_text("{not json")
    fails("import-annotations", str(bad), expect="not valid JSON")
    (bad / "annotations.json").write_text('{"images": ' + "[" * 50_000 + "]" * 50_000 + "}")
    fails("import-annotations", str(bad), expect="nested deeper than 100 levels")
    coco = json.loads((out / "annotations.json").read_text())
    coco["annotations"][0]["segmentation"]["counts"] = "!!"
    (bad / "annotations.json").write_text(json.dumps(coco))
    fails("import-annotations", str(bad), expect="annotation 1: segmentation.counts")
    with app.app_context():
        assert db.session.execute(db.select(Annotation)).scalars().all() == []  # nothing half-imported


@pytest.mark.parametrize("name", ["a/b", ".hidden", "", "x\\y"])
def test_names_are_single_path_components(name):
    safe = exchange.safe(name)
    assert "/" not in safe and "\\" not in safe and not safe.startswith(".") and safe


def _hostile_link(zf):
    info = zipfile.ZipInfo("masks/cooking/rec/00009.png")
    info.external_attr = (stat.S_IFLNK | 0o777) << 16
    zf.writestr(info, "/etc/passwd")


HOSTILE_MEMBERS = {
    "traversal": (lambda zf: zf.writestr("masks/../../evil.png", b"x"), "unsafe path 'masks/../../evil.png'"),
    "absolute": (lambda zf: zf.writestr("/tmp/evil.png", b"x"), "unsafe path '/tmp/evil.png'"),
    "drive": (lambda zf: zf.writestr("C:/evil.png", b"x"), "unsafe path 'C:/evil.png'"),
    "link": (_hostile_link, "'masks/cooking/rec/00009.png' is a link"),
    "bomb": (lambda zf: zf.writestr("masks/pad.png", b"\0" * (50 * 1024**2), zipfile.ZIP_DEFLATED),
             "'masks/pad.png' inflates"),
}


@pytest.mark.parametrize("kind", [*HOSTILE_MEMBERS, "lying header"])
def test_hostile_zips_are_refused_naming_the_member_and_import_nothing(app, runner, tmp_path, kind):
    from tests.app.test_import_safety import lie_about_size

    labelled_dataset(app, recording(tmp_path / "rec"))
    export = tmp_path / "out"
    assert runner.invoke(args=["egonet", "export", "--out", str(export)]).exit_code == 0
    with app.app_context():
        db.session.execute(db.delete(Instance))
        db.session.execute(db.delete(Annotation))
        db.session.commit()
    archive = tmp_path / "hostile.zip"
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, data in files(export).items():
            zf.writestr(name, data)
        if kind in HOSTILE_MEMBERS:
            HOSTILE_MEMBERS[kind][0](zf)
    if kind == "lying header":
        lie_about_size(archive, "annotations.json", 100)
    expect = HOSTILE_MEMBERS[kind][1] if kind in HOSTILE_MEMBERS else "'annotations.json' does not match its header"

    result = runner.invoke(args=["egonet", "import-annotations", str(archive)])
    assert result.exit_code != 0 and result.output.strip().count("\n") == 0, result.output
    assert result.output.startswith("Error: ") and expect in result.output
    with app.app_context():
        assert db.session.execute(db.select(Annotation)).first() is None
    assert not (tmp_path / "evil.png").exists()
