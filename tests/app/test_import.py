import json
import uuid
import zipfile

import cv2
import numpy as np
import pytest

from app.extensions import db
from app.models import Activity, Annotation, Frame, Status
from app.services import media
from app.services.importing import ImportProblem, import_path
from app.services.storage import store
from egonet import io
from egonet.dhg import GRAY, decode_dhg
from tests.app.factories import image_folder, rgb_image, video_file
from tests.realdata import EGONET_SAMPLES, PRIMESENSE



def frames():
    return db.session.execute(db.select(Frame).order_by(Frame.index)).scalars().all()


def media_files(app) -> list[str]:
    return sorted(entry.key for entry in store().list("media"))


@pytest.mark.both_storages
def test_folder_import_stores_content_addressed_media(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=4)
    report = import_path(folder, activity="cooking")
    assert (report.added, report.skipped, report.sequence) == (4, 0, "rec")
    fs = frames()
    assert [f.index for f in fs] == [0, 1, 2, 3]
    for i, f in enumerate(fs):
        assert (f.width, f.height) == (64, 48)
        data = media.read(f.rgb_path)
        assert media.sha256(data) == f.content_hash
        assert f.rgb_path == f"{f.content_hash[:2]}/{f.content_hash}.png"
        np.testing.assert_array_equal(io.decode_image(data), rgb_image(i))
    assert len(media_files(ctx)) == 4


def test_reimport_adds_nothing(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=3)
    import_path(folder, activity="cooking")
    again = import_path(folder, activity="cooking")
    assert (again.added, again.skipped) == (0, 3)
    assert len(frames()) == 3


def test_stride_keeps_every_nth_image(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=7)
    import_path(folder, activity="cooking", stride=3)
    assert [f.index for f in frames()] == [0, 3, 6]


def test_video_import_with_stride(ctx, tmp_path):
    path = video_file(tmp_path / "walk.avi", n=10)
    report = import_path(path, activity="hotel", stride=4)
    assert (report.added, report.sequence) == (3, "walk")
    fs = frames()
    assert [f.index for f in fs] == [0, 4, 8]
    assert fs[1].timestamp_s == pytest.approx(0.4)
    assert len({f.content_hash for f in fs}) == 3


@pytest.mark.both_storages
def test_depth_is_paired_by_stem_and_dhg_computed_with_intrinsics(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=2, depth=True, intrinsics=True)
    import_path(folder, activity="desk work")
    for i, f in enumerate(frames()):
        assert (f.fx, f.fy, f.cx, f.cy) == (50.0, 50.0, 32.0, 24.0)
        depth = io.read_depth(media.local_path(f.depth_path))
        assert depth[0, 0] == 0.0
        assert depth[5, 5] == pytest.approx(1.0 + 0.25 * i, abs=1e-3)
        dhg = io.read_dhg(media.local_path(f.dhg_path))
        assert dhg.shape == (48, 64, 3)
        # Stored in the authors' order: the computed DHG decodes to the depth it came from.
        rgb = io.read_image(media.local_path(f.rgb_path))
        np.testing.assert_array_equal(dhg[..., GRAY], cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
        decoded = decode_dhg(dhg)
        assert np.isnan(decoded.depth[0, 0])
        assert decoded.depth[5, 5] == pytest.approx(1.0 + 0.25 * i, abs=0.016)


def test_npy_depth_and_given_dhg(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=1)
    (folder / "depth").mkdir()
    np.save(folder / "depth" / "00000.npy", np.full((48, 64), 2.5, np.float32))
    (folder / "dhg").mkdir()
    dhg = rgb_image(99)
    (folder / "dhg" / "00000.png").write_bytes(io.encode_png(dhg))
    import_path(folder, activity="grocery")
    (f,) = frames()
    assert io.read_depth(media.local_path(f.depth_path))[3, 3] == pytest.approx(2.5)
    np.testing.assert_array_equal(io.read_dhg(media.local_path(f.dhg_path)), dhg)


@pytest.mark.both_storages
def test_masks_become_annotations(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=2, masks=True)
    report = import_path(folder, activity="dining", mask_author="wearer", mask_status=Status.REVIEWED)
    assert report.annotations == 2
    anns = db.session.execute(db.select(Annotation)).scalars().all()
    assert {a.author.username for a in anns} == {"wearer"}
    assert {a.status for a in anns} == {Status.REVIEWED}
    mask = io.read_mask(media.local_path(anns[0].mask_path))
    assert mask.sum() == 10 * 25 or mask.sum() == 10 * 24
    assert len(anns[0].instances) == 1


def assert_nothing_imported(ctx):
    assert db.session.execute(db.select(Frame)).first() is None
    assert db.session.execute(db.select(Activity)).first() is None
    assert media_files(ctx) == []


@pytest.mark.both_storages
def test_corrupt_image_stops_and_names_the_file(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=4)
    bad = folder / "rgb" / "00002.png"
    bad.write_bytes(bad.read_bytes()[:40])  # truncated
    with pytest.raises(io.MediaError, match="00002.png"):
        import_path(folder, activity="cooking")
    assert_nothing_imported(ctx)


def test_depth_size_mismatch_stops_and_names_the_file(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=3, depth=True)
    (folder / "depth" / "00001.png").write_bytes(io.encode_depth_png(np.ones((10, 10), np.float32)))
    with pytest.raises(io.MediaError, match=r"00001\.png.*10x10 does not match the frame's 64x48"):
        import_path(folder, activity="cooking")
    assert_nothing_imported(ctx)


@pytest.mark.both_storages
def test_failed_reimport_keeps_earlier_frames_and_media(ctx, tmp_path):
    folder = image_folder(tmp_path / "rec", n=2)
    import_path(folder, activity="cooking")
    before = media_files(ctx)
    (folder / "rgb" / "00009.png").write_bytes(b"not an image")
    with pytest.raises(io.MediaError, match="00009.png"):
        import_path(folder, activity="cooking")
    assert len(frames()) == 2
    assert media_files(ctx) == before


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: (d / "rgb" / "notes.txt").write_text("hi"), "unknown format '.txt'"),
        (lambda d: (d / "depth").mkdir() or (d / "depth" / "00000.tiff").write_bytes(b"x"), "unknown format '.tiff'"),
        (lambda d: (d / "camera.json").write_text(json.dumps({"fx": 1})), "camera.json"),
    ],
)
def test_unknown_formats_and_bad_intrinsics_are_refused(ctx, tmp_path, make, message):
    folder = image_folder(tmp_path / "rec", n=2)
    make(folder)
    with pytest.raises(ValueError, match=message):
        import_path(folder, activity="cooking")
    assert_nothing_imported(ctx)


def test_bad_paths_and_options(ctx, tmp_path):
    with pytest.raises(ImportProblem, match="no such file"):
        import_path(tmp_path / "missing", activity="x")
    (tmp_path / "clip.mkv").write_bytes(b"x")
    with pytest.raises(ImportProblem, match="unknown format '.mkv'"):
        import_path(tmp_path / "clip.mkv", activity="x")
    (tmp_path / "broken.mp4").write_bytes(b"not a video")
    with pytest.raises(io.MediaError, match="broken.mp4"):
        import_path(tmp_path / "broken.mp4", activity="x")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ImportProblem, match="no images"):
        import_path(tmp_path / "empty", activity="x")
    with pytest.raises(ImportProblem, match="--stride"):
        import_path(tmp_path / "empty", activity="x", stride=0)
    assert_nothing_imported(ctx)


@pytest.mark.both_storages
def test_a_recording_in_a_bucket_imports_as_a_folder_does(ctx, runner, tmp_path, seaweedfs):
    folder = image_folder(tmp_path / "rec", n=3, depth=True, intrinsics=True, masks=True)
    with zipfile.ZipFile(tmp_path / "take2.zip", "w") as zf:
        zf.write(folder / "rgb" / "00000.png", "rgb/00000.png")
    prefix = f"sources-{uuid.uuid4().hex[:8]}"
    client = seaweedfs.client()
    for path in [*folder.rglob("*.*"), tmp_path / "take2.zip"]:
        client.put_object(Bucket="egonet-test", Key=f"{prefix}/{path.relative_to(tmp_path).as_posix()}", Body=path.read_bytes())

    result = runner.invoke(args=["egonet", "import", f"s3://egonet-test/{prefix}/rec/", "--activity", "cooking"])
    assert result.exit_code == 0, result.output
    assert ("cooking / rec: 3 frames added (depth: 3, DHG: 3, intrinsics: found), 0 already present, "
            "3 masks imported") in result.output
    assert import_path(folder, activity="cooking").skipped == 3  # the same frames as the folder's
    assert frames()[0].sequence.source == f"s3://egonet-test/{prefix}/rec/"
    result = runner.invoke(args=["egonet", "import", f"s3://egonet-test/{prefix}/take2.zip", "--activity", "cooking"])
    assert "cooking / take2: 1 frame added" in result.output, result.output

    for url, reason in ((f"s3://egonet-test/{prefix}/none", "no such folder or object"), ("s3://egonet-test", "name a folder")):
        result = runner.invoke(args=["egonet", "import", url, "--activity", "cooking"])
        assert result.exit_code == 1 and reason in result.output and result.output.count("\n") == 1, result.output


@pytest.mark.skipif(not (PRIMESENSE).exists(), reason="shared data not present")
def test_real_rgbd_frames(ctx):
    report = import_path(PRIMESENSE, activity="room")
    assert report.added == 3
    assert report.summary() == ("3 frames added (depth: 3, DHG: 3, intrinsics: found), 0 already present, "
                                "0 masks imported")
    f = frames()[0]
    assert (f.width, f.height, f.fx, f.cx) == (640, 480, 525.0, 319.5)
    depth = io.read_depth(media.local_path(f.depth_path))
    assert 0.3 < np.median(depth[depth > 0]) < 5.0
    assert f.dhg_path is not None


@pytest.mark.skipif(not (EGONET_SAMPLES).exists(), reason="shared data not present")
def test_real_egonet_samples_pair_rgb_and_dhg(ctx):
    report = import_path(EGONET_SAMPLES, activity="samples")
    assert report.added == 3
    assert report.summary().startswith("3 frames added (depth: 0, DHG: 3, intrinsics: none)")
    for f in frames():
        assert f.dhg_path is not None and f.depth_path is None
        assert (f.width, f.height) == (514, 386)
        # The authors' files import as they are, and their gray channel decodes as gray, not as depth.
        stored = io.read_dhg(media.local_path(f.dhg_path))
        np.testing.assert_array_equal(stored, io.read_dhg(next((EGONET_SAMPLES / "dhg").glob(f"{f.source_name}.*"))))
        gray = cv2.cvtColor(io.read_image(media.local_path(f.rgb_path)), cv2.COLOR_RGB2GRAY).ravel()
        decoded = decode_dhg(stored)
        assert np.corrcoef(decoded.gray.ravel(), gray)[0, 1] > 0.95
        assert abs(np.corrcoef(np.nan_to_num(decoded.depth).ravel(), gray)[0, 1]) < 0.5
