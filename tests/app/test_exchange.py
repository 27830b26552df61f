"""Export (PNG per frame, COCO JSON with RLE) and import back: a round trip is exact."""

import io as bytes_io
import json
import stat
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
from app.services import exchange, labelling
from app.services.importing import import_path
from app.services.users import create_user
from egonet import io
from tests.app.factories import image_folder, rgb_image

SIZE = (48, 64)


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


def labelled_dataset(app, folder: Path) -> dict[str, list[np.ndarray]]:
    """Frames with every kind of annotation; returns the exported frames' instance masks by name."""
    with app.app_context():
        import_path(folder, activity="cooking")
        frames = db.session.execute(db.select(Frame).order_by(Frame.index, Frame.source_name, Frame.id)).scalars().all()
        ann, _ = create_user("ann", Role.ANNOTATOR, "ann-password")
        rev, _ = create_user("rev", Role.REVIEWER, "rev-password")
        two = [blob(2, 20, 3, 30), blob(25, 40, 35, 60)]
        save(frames[0], ann, *two, kinds=["tactile", "visual"], seconds=41.25)
        save(frames[1], ann, no_action_object=True)
        accepted = save(frames[2], ann, blob(10, 30, 10, 50), seconds=3)
        labelling.review_annotation(accepted, rev, version=accepted.version, decision="accept", comment="Nice.")
        save(frames[3], ann, blob(0, 5, 0, 5), status=None)  # in progress: not exported by default
        save(frames[4], ann, blob(30, 48, 0, 64))
        return {
            "cooking/rec/00000": two,
            f"cooking/rec/{_stem(frames[1])}": [],
            f"cooking/rec/{_stem(frames[2])}": [blob(10, 30, 10, 50)],
            f"cooking/rec/{_stem(frames[4])}": [blob(30, 48, 0, 64)],
        }


def _stem(frame: Frame) -> str:
    return frame.source_name if frame.source_name != "00001" else f"00001~{frame.content_hash[:12]}"


def wipe(app) -> None:
    """An empty database: no frames, users or annotations (media files stay, as on a new server)."""
    with app.app_context():
        with db.engine.begin() as conn:
            for table in reversed(db.metadata.sorted_tables):
                conn.execute(table.delete())


def files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_export_import_export_is_bit_for_bit(app, runner, tmp_path):
    folder = recording(tmp_path / "rec")
    expected = labelled_dataset(app, folder)
    first, second = tmp_path / "first", tmp_path / "second"
    result = runner.invoke(args=["egonet", "export", "--out", str(first)])
    assert result.exit_code == 0, result.output
    assert "4 frames, 4 action-objects exported" in result.output

    exported = files(first)
    assert sorted(exported) == ["annotations.json"] + sorted(f"masks/{name}.png" for name in expected)
    for name, masks in expected.items():
        union = io.decode_mask(exported[f"masks/{name}.png"])
        assert np.array_equal(union, np.logical_or.reduce(masks) if masks else np.zeros(SIZE, bool))
        assert set(np.unique(cv2.imdecode(np.frombuffer(exported[f"masks/{name}.png"], np.uint8), -1))) <= {0, 255}

    wipe(app)
    with app.app_context():
        import_path(folder, activity="cooking")
    result = runner.invoke(args=["egonet", "import-annotations", str(first)])
    assert result.exit_code == 0, result.output
    assert "4 annotations (4 action-objects) imported" in result.output
    result = runner.invoke(args=["egonet", "export", "--out", str(second)])
    assert result.exit_code == 0, result.output
    assert files(second) == exported

    with app.app_context():
        reviewed = db.session.execute(db.select(Annotation).filter_by(status=Status.REVIEWED)).scalar_one()
        assert reviewed.review_comment == "Nice." and reviewed.reviewer.username == "rev"
        author = db.session.execute(db.select(User).filter_by(username="ann")).scalar_one()
        assert not author.active and author.password_hash is None  # created by the import, cannot sign in


def test_coco_file_reads_in_pycocotools(app, runner, tmp_path):
    expected = labelled_dataset(app, recording(tmp_path / "rec"))
    assert runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "out"), "--format", "coco"]).exit_code == 0
    assert not (tmp_path / "out" / "masks").exists()
    coco = COCO(str(tmp_path / "out" / "annotations.json"))

    def decoded(annotation):
        with warnings.catch_warnings():  # pycocotools' Cython code predates numpy 2's __array__ copy keyword
            warnings.simplefilter("ignore", DeprecationWarning)
            return coco.annToMask(annotation).astype(bool)

    assert len(coco.getImgIds()) == 4 and coco.loadCats(1)[0]["name"] == "action-object"
    for image in coco.loadImgs(coco.getImgIds()):
        name = image["file_name"].rsplit(".", 1)[0]
        anns = coco.loadAnns(coco.getAnnIds(imgIds=image["id"]))
        assert len(anns) == len(expected[name])
        for a, mask in zip(anns, expected[name]):
            assert np.array_equal(decoded(a), mask)
            assert a["area"] == mask.sum()
        assert image["egonet"]["no_action_object"] == (not expected[name])
    first = coco.loadImgs(1)[0]
    assert first["egonet"]["time_spent_s"] == 41.25 and first["egonet"]["author"] == "ann"
    kinds = [a["egonet"]["kind"] for a in coco.loadAnns(coco.getAnnIds(imgIds=1))]
    assert kinds == ["tactile", "visual"]


def test_png_masks_alone_round_trip(app, runner, tmp_path):
    folder = recording(tmp_path / "rec")
    labelled_dataset(app, folder)
    assert runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "a"), "--format", "png"]).exit_code == 0
    wipe(app)
    with app.app_context():
        import_path(folder, activity="cooking")
    result = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a"), "--author", "wearer"])
    assert result.exit_code == 0, result.output
    assert runner.invoke(args=["egonet", "export", "--out", str(tmp_path / "b"), "--format", "png"]).exit_code == 0
    assert files(tmp_path / "b") == files(tmp_path / "a")
    with app.app_context():
        annotations = db.session.execute(db.select(Annotation)).scalars().all()
        assert {a.author.username for a in annotations} == {"wearer"} and {a.status for a in annotations} == {Status.DONE}
        assert sum(a.no_action_object for a in annotations) == 1
    # Importing again keeps what is there, unless asked to replace it.
    again = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a"), "--author", "wearer"])
    assert "0 annotations (0 action-objects) imported, 4 kept as they were" in again.output
    replaced = runner.invoke(args=["egonet", "import-annotations", str(tmp_path / "a"), "--author", "wearer", "--replace"])
    assert "4 annotations" in replaced.output


def test_download_and_its_filters(app, admin_client, tmp_path):
    labelled_dataset(app, recording(tmp_path / "rec"))
    with admin_client.get("/label/export?format=both&status=in_progress&status=done") as response:
        assert response.status_code == 200 and response.mimetype == "application/zip"
        assert response.headers["X-Exported-Frames"] == "4"  # done frames and the one in progress
        archive = zipfile.ZipFile(bytes_io.BytesIO(response.data))
        names = archive.namelist()
    assert "annotations.json" in names and "masks/cooking/rec/00003.png" in names
    with admin_client.get("/label/export?activity=cooking&format=png") as response:
        assert response.headers["X-Exported-Frames"] == "4"
    for query in ("format=tiff", "status=lost", "activity=gardening"):
        with admin_client.get(f"/label/export?{query}") as response:
            assert response.status_code == 400, query

    path = tmp_path / "download.zip"
    with admin_client.get("/label/export") as response:
        path.write_bytes(response.data)
    with app.app_context():
        db.session.execute(db.delete(Instance))
        db.session.execute(db.delete(Annotation))
        db.session.commit()
        report = exchange.import_annotations(path)
        assert (report.annotations, report.instances) == (4, 4)


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
    fails("export", "--out", str(tmp_path / "x"), "--activity", "gardening", expect="no activity named 'gardening'")
    assert not (tmp_path / "x").exists()
    fails("import-annotations", str(tmp_path / "nothing"), expect="no such file or folder")

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
    coco = json.loads((out / "annotations.json").read_text())
    coco["annotations"][0]["segmentation"]["counts"] = "!!"
    (bad / "annotations.json").write_text(json.dumps(coco))
    fails("import-annotations", str(bad), expect="annotation 1: segmentation.counts")
    with app.app_context():
        assert db.session.execute(db.select(Annotation)).scalars().all() == []  # nothing half-imported


@pytest.mark.parametrize("name", ["a/b", ".hidden", "", "x\\y"])
def test_names_are_single_path_components(name):
    safe = exchange._safe(name)
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
