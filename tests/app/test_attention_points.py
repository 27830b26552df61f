"""Ground truth from attention points (the paper's Table 4): `flask egonet import-points`."""

import json
from pathlib import Path

import numpy as np
import pytest

from app.extensions import db
from app.models import Annotation, AttentionPoints, Frame, Status
from app.services import scoring
from app.services.attention_points import PointsProblem, import_points
from app.services.ground_truth import ground_truths, mask_of
from app.services.importing import import_path
from tests.app.factories import image_folder


def frames():
    return db.session.execute(db.select(Frame).order_by(Frame.index)).scalars().all()


def media_files(app) -> list[Path]:
    root = Path(app.config["STORAGE_URL"]) / "media"
    return sorted(p for p in root.rglob("*") if p.is_file()) if root.exists() else []


def disc(shape, points, radius):
    """The pixels within ``radius`` of a point, computed directly."""
    rows, cols = np.mgrid[: shape[0], : shape[1]]
    out = np.zeros(shape, bool)
    for x, y in points:
        out |= (cols - x) ** 2 + (rows - y) ** 2 <= radius**2
    return out


def write_csv(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_points_become_each_frames_ground_truth_and_a_frame_without_one_has_no_action_object(ctx, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=3), activity="kids")
    csv = write_csv(tmp_path / "points.csv", "frame,x,y\n00000,10,12\n00000,40.5,30\n00001,63,47\n")
    report = import_points(csv, activity="kids", sigma=5)
    assert (report.frames, report.with_points, report.points, report.without_points, report.replaced) == (3, 2, 3, 1, 0)
    f0, f1, f2 = frames()
    chosen = ground_truths([f0.id, f1.id, f2.id])
    assert {a.author.username for a in chosen.values()} == {"import"}
    assert {a.status for a in chosen.values()} == {Status.REVIEWED}
    assert np.array_equal(mask_of(chosen[f0.id]), disc((48, 64), [(10, 12), (40.5, 30)], 5))
    assert np.array_equal(mask_of(chosen[f1.id]), disc((48, 64), [(63, 47)], 5))
    assert chosen[f2.id].no_action_object and not mask_of(chosen[f2.id]).any()
    record = db.session.execute(db.select(AttentionPoints).filter_by(annotation_id=chosen[f0.id].id)).scalar_one()
    assert record.points == [[10.0, 12.0], [40.5, 30.0]] and record.sigma_px == 5.0 and not record.sigma_scaled
    assert record.source == "points.csv"


def test_without_sigma_the_click_studys_width_is_scaled_to_the_frame(ctx, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=2, size=(60, 160)), activity="kids")
    report = import_points(write_csv(tmp_path / "p.csv", "frame,x,y\n00001,80,30\n"), activity="kids")
    sigma = 60 * 160 / 1280  # the paper's 60 px at 1280 px wide, as the click study scales it
    assert "sigma 7.5 px (60 px at 1280 px wide" in report.sigma
    annotation = ground_truths([frames()[1].id])[frames()[1].id]
    assert annotation.attention_points.sigma_px == sigma and annotation.attention_points.sigma_scaled
    assert np.array_equal(mask_of(annotation), disc((60, 160), [(80, 30)], sigma))


@pytest.mark.parametrize(("text", "message"), [
    ("frame,x,y\n00000,1,1\n\nx,3,4\n", "points.csv line 4: frame 'x' is not in activity 'kids'"),
    ("frame,x,y\n00001,64,10\n", "points.csv line 2: (64, 10) lies outside frame '00001' (64x48: x in [-0.5, 63.5]"),
    ("frame,x,y\n00001,3,-1\n", "points.csv line 2: (3, -1) lies outside frame '00001'"),
    ("frame,x,y\n00000,1,1\n00001,ten,3\n", "points.csv line 3: x 'ten' is not a number"),
    ("frame,x,y\n00001,3,nan\n", "points.csv line 2: y 'nan' is not a number"),
    ("frame,x,y\n00001,3\n", "points.csv line 2: 2 values, expected 3 (frame,x,y)"),
    ("name,col,row\n00001,3,4\n", "points.csv line 1: the header must be frame,x,y"),
    ("frame,x,y\n", "points.csv: no points"),
    ("frame,x,y\n00000,1,1\n" + "a" * 200_000 + ",1,1\n", "points.csv line 3: not readable as CSV (field larger than"),
    ("frame,x,y\n00000,1\x00,1\n", "points.csv: holds a NUL character"),
])
def test_a_bad_row_names_its_line_and_nothing_is_imported(app, ctx, runner, tmp_path, text, message):
    import_path(image_folder(tmp_path / "rec", n=2), activity="kids")
    before = media_files(app)
    csv = write_csv(tmp_path / "points.csv", text)
    with pytest.raises(PointsProblem, match=None) as caught:
        import_points(csv, activity="kids", sigma=4)
    assert message in caught.value.message
    result = runner.invoke(args=["egonet", "import-points", str(csv), "--activity", "kids"])
    assert result.exit_code != 0 and message in result.output
    assert db.session.scalar(db.select(db.func.count()).select_from(Annotation)) == 0
    assert db.session.scalar(db.select(db.func.count()).select_from(AttentionPoints)) == 0
    assert media_files(app) == before


def test_a_bad_row_after_a_good_import_keeps_the_earlier_points(ctx, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=2), activity="kids")
    import_points(write_csv(tmp_path / "a.csv", "frame,x,y\n00000,5,5\n"), activity="kids", sigma=3)
    with pytest.raises(PointsProblem, match="b.csv line 3"):
        import_points(write_csv(tmp_path / "b.csv", "frame,x,y\n00001,5,5\n00001,500,5\n"), activity="kids", sigma=3)
    records = db.session.execute(db.select(AttentionPoints).order_by(AttentionPoints.id)).scalars().all()
    assert [r.points for r in records] == [[[5.0, 5.0]], []] and {r.source for r in records} == {"a.csv"}


def test_importing_again_replaces_the_points(ctx, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=2), activity="kids")
    import_points(write_csv(tmp_path / "a.csv", "frame,x,y\n00000,5,5\n"), activity="kids", sigma=3)
    report = import_points(write_csv(tmp_path / "b.csv", "frame,x,y\n00001,20,20\n"), activity="kids", sigma=6)
    assert report.replaced == 2
    f0, f1 = frames()
    assert db.session.scalar(db.select(db.func.count()).select_from(Annotation)) == 2
    assert db.session.scalar(db.select(db.func.count()).select_from(AttentionPoints)) == 2
    chosen = ground_truths([f0.id, f1.id])
    assert chosen[f0.id].no_action_object and not mask_of(chosen[f0.id]).any()
    assert np.array_equal(mask_of(chosen[f1.id]), disc((48, 64), [(20, 20)], 6))
    assert chosen[f1.id].attention_points.source == "b.csv"


def test_masks_of_the_same_author_are_never_overwritten(ctx, runner, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=2, masks=True), activity="kids")  # author "import", done
    csv = write_csv(tmp_path / "points.csv", "frame,x,y\n00000,5,5\n")
    result = runner.invoke(args=["egonet", "import-points", str(csv), "--activity", "kids", "--sigma", "3"])
    assert result.exit_code != 0
    assert "frame '00000' already has an annotation by 'import' that did not come from points" in result.output
    result = runner.invoke(args=["egonet", "import-points", str(csv), "--activity", "kids", "--sigma", "3", "--author", "points"])
    assert result.exit_code == 0, result.output
    assert "kids: 1 point on 1 frame, 1 frame without a point" in result.output
    f0, f1 = frames()
    chosen = ground_truths([f0.id, f1.id])  # reviewed wins over the done masks
    assert {a.author.username for a in chosen.values()} == {"points"}
    assert np.array_equal(mask_of(chosen[f0.id]), disc((48, 64), [(5, 5)], 3))


def test_unknown_activity_and_bad_sigma_are_refused(ctx, runner, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=1), activity="kids")
    csv = write_csv(tmp_path / "points.csv", "frame,x,y\n00000,5,5\n")
    with pytest.raises(PointsProblem, match="no activity 'cats'"):
        import_points(csv, activity="cats")
    result = runner.invoke(args=["egonet", "import-points", str(csv), "--activity", "kids", "--sigma", "-2"])
    assert result.exit_code != 0 and "--sigma must be a positive number of pixels, got -2" in result.output


def test_the_frame_page_and_every_report_say_the_ground_truth_is_attention_points(app, ctx, admin_client, tmp_path):
    import_path(image_folder(tmp_path / "rec", n=3), activity="kids")
    import_path(image_folder(tmp_path / "rec2", n=3, masks=True), activity="cooking")
    import_points(write_csv(tmp_path / "points.csv", "frame,x,y\n00000,10,12\n00001,20,20\n"), activity="kids", sigma=5)
    kids = [f for f in frames() if f.sequence.activity.name == "kids"]
    page = admin_client.get(f"/frames/{kids[0].id}").get_data(as_text=True)
    assert "ground truth: attention points" in page
    assert "made from attention points (1), sigma 5 px; binarised within one sigma, from points.csv: (10, 12)" in page
    empty = admin_client.get(f"/frames/{kids[2].id}").get_data(as_text=True)
    assert "attention points (none: no action-object), sigma 5 px" in empty

    report = scoring.build_report(run_ids=[], study_ids=[], resamples=0)
    said = report.provenance.ground_truth
    assert set(said) == {"kids"} and said["kids"].startswith("attention points, sigma 5 px: a Gaussian around each point, "
                                                               "binarised within one sigma")
    line = f"Ground truth: kids: {said['kids']}; other activities: drawn masks."
    assert line in report.to_table()
    rows = report.to_csv().splitlines()
    assert "ground truth" in rows[0] and "kids: attention points, sigma 5 px" in rows[1]
    assert json.loads(report.to_json())["ground_truth"] == {"kids": said["kids"]}
    assert "% Ground truth: kids: attention points, sigma 5 px" in report.to_latex()
    assert "The ground truth of kids is attention points, sigma 5 px" in report.to_methods()
    assert report.provenance.empty_frames["kids"] == 1  # the frame without a point: no action-object
    means = scoring.build_report(run_ids=[], study_ids=[], resamples=0, metric="ois-mean")  # policy leave-out
    assert means.provenance.empty_frames["kids"] == 1
    assert {c.n_frames for r in means.rows if (c := r.cells.get("kids")) is not None} == {2}
    html = admin_client.get("/scores/?chosen=1&baselines=1&resamples=0").get_data(as_text=True)
    assert "Ground truth" in html and "attention points, sigma 5 px" in html


def test_admins_import_points_from_the_activity_page(app, ctx, admin_client, tmp_path):
    import io as bytes_io

    import_path(image_folder(tmp_path / "rec", n=2), activity="kids")
    activity_id = frames()[0].sequence.activity_id
    page = admin_client.get(f"/activities/{activity_id}").get_data(as_text=True)
    assert 'id="points-import"' in page and f'action="/activities/{activity_id}/points"' in page
    bad = admin_client.post(f"/activities/{activity_id}/points", content_type="multipart/form-data",
                            data={"points": (bytes_io.BytesIO(b"frame,x,y\n00000,1,1\nzz,1,1\n"), "my points.csv")})
    assert bad.status_code == 400 and "my_points.csv line 3: frame &#39;zz&#39; is not in activity &#39;kids&#39;" in bad.get_data(as_text=True)
    assert db.session.scalar(db.select(db.func.count()).select_from(AttentionPoints)) == 0
    done = admin_client.post(f"/activities/{activity_id}/points", content_type="multipart/form-data", follow_redirects=True,
                             data={"points": (bytes_io.BytesIO(b"frame,x,y\n00001,20,20\n"), "p.csv"), "sigma": "6"})
    assert done.status_code == 200 and "kids: 1 point on 1 frame, 1 frame without a point" in done.get_data(as_text=True)
    f0, f1 = frames()
    chosen = ground_truths([f0.id, f1.id])
    assert np.array_equal(mask_of(chosen[f1.id]), disc((48, 64), [(20, 20)], 6)) and chosen[f0.id].no_action_object
    assert chosen[f1.id].attention_points.source == "p.csv"
    missing = admin_client.post(f"/activities/{activity_id}/points", data={"sigma": "0.1"})
    assert missing.status_code == 400 and "choose a CSV file of points" in missing.get_data(as_text=True)
    text = admin_client.post(f"/activities/{activity_id}/points", data={"points": "not a file"})  # a field, not a file
    assert text.status_code == 400 and "choose a CSV file of points" in text.get_data(as_text=True)
