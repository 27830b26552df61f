import numpy as np
import pytest
from werkzeug.security import check_password_hash

from app.extensions import db
from app.models import Frame, Role, User
from tests.app.factories import image_folder


def test_import_command_reports_and_is_idempotent(ctx, runner, tmp_path):
    folder = image_folder(tmp_path / "rec", n=3)
    result = runner.invoke(args=["egonet", "import", str(folder), "--activity", "cooking", "--sequence", "take1"])
    assert result.exit_code == 0, result.output
    assert "cooking / take1: 3 frames added (depth: 0, DHG: 0, intrinsics: none), 0 already present" in result.output
    result = runner.invoke(args=["egonet", "import", str(folder), "--activity", "cooking", "--sequence", "take1"])
    assert "0 frames added (depth: 0, DHG: 0, intrinsics: none), 3 already present" in result.output
    assert len(db.session.execute(db.select(Frame)).all()) == 3


def test_import_command_fails_with_one_line_naming_the_file(ctx, runner, tmp_path):
    folder = image_folder(tmp_path / "rec", n=2)
    (folder / "rgb" / "00001.png").write_bytes(b"garbage")
    result = runner.invoke(args=["egonet", "import", str(folder), "--activity", "cooking"])
    assert result.exit_code != 0
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "00001.png" in errors[0]
    assert "Traceback" not in result.output
    assert db.session.execute(db.select(Frame)).first() is None


def test_import_command_validates_options(ctx, runner, tmp_path):
    result = runner.invoke(args=["egonet", "import", str(tmp_path), "--activity", "x", "--stride", "0"])
    assert result.exit_code == 2 and "--stride" in result.output
    result = runner.invoke(args=["egonet", "import", str(tmp_path / "nope"), "--activity", "x"])
    assert result.exit_code == 1 and "no such file" in result.output


def test_create_user_with_password_and_generated(ctx, runner):
    result = runner.invoke(args=["egonet", "create-user", "ana", "--role", "annotator", "--password", "s3cret-pass"])
    assert result.exit_code == 0, result.output
    ana = db.session.execute(db.select(User).filter_by(username="ana")).scalar_one()
    assert ana.role is Role.ANNOTATOR
    assert check_password_hash(ana.password_hash, "s3cret-pass")

    result = runner.invoke(args=["egonet", "create-user", "boss", "--role", "admin"])
    generated = result.output.split("password: ")[1].strip()
    boss = db.session.execute(db.select(User).filter_by(username="boss")).scalar_one()
    assert check_password_hash(boss.password_hash, generated)


def test_create_user_errors(ctx, runner):
    runner.invoke(args=["egonet", "create-user", "ana", "--role", "annotator", "--password", "s3cret-pass"])
    result = runner.invoke(args=["egonet", "create-user", "ana", "--role", "reviewer", "--password", "another-pass"])
    assert result.exit_code == 1 and "already exists" in result.output
    result = runner.invoke(args=["egonet", "create-user", "ana", "--role", "annotator", "--if-missing"])
    assert result.exit_code == 0 and "keeping it" in result.output
    result = runner.invoke(args=["egonet", "create-user", "bob", "--role", "wizard"])
    assert result.exit_code == 2 and "--role" in result.output
    result = runner.invoke(args=["egonet", "create-user", "bob", "--role", "admin", "--password", "short"])
    assert result.exit_code == 1 and "at least 10" in result.output


def test_demo_command_creates_reviewed_ground_truth_and_leaves_the_last_frames_to_label(ctx, runner):
    args = ["egonet", "demo", "--frames-per-activity", "2", "--width", "96", "--height", "72", "--seed", "3"]
    result = runner.invoke(args=args)
    assert result.exit_code == 0, result.output
    assert "demo: 14 frames added, 0 already present, in 7 activities; 7 of the new frames are left to label" in result.output
    # One labelled frame per activity: too few for the quick-start run, which the demo says and skips.
    assert "demo: no quick-start run: a single split needs an activity with at least two labelled frames" in result.output
    from app.models import Annotation, Status
    from app.services import media
    from egonet import io

    anns = db.session.execute(db.select(Annotation)).scalars().all()
    assert len(anns) == 7
    assert {a.status for a in anns} == {Status.REVIEWED}
    assert {a.author.username for a in anns} == {"demo"}
    # A quarter of 2 rounds to 1 left unlabelled per activity: the last one.
    assert {a.frame.index for a in anns} == {0}
    assert len({a.frame.sequence.activity_id for a in anns}) == 7
    unlabelled = db.session.execute(db.select(Frame).where(~Frame.annotations.any())).scalars().all()
    assert [f.index for f in unlabelled] == [1] * 7
    for a in anns:
        mask = io.read_mask(media.local_path(a.mask_path))
        depth = io.read_depth(media.local_path(a.frame.depth_path))
        assert mask.any() and (depth[mask] > 0).all()
        assert a.frame.dhg_path is not None and a.frame.fx is not None
    for f in unlabelled:
        assert f.depth_path is not None and f.dhg_path is not None and f.fx is not None
    # Same seed again: nothing new.
    result = runner.invoke(args=args)
    assert "demo: 0 frames added, 14 already present, in 7 activities; 0 of the new frames are left to label" in result.output


def test_demo_command_unlabelled_fraction_0_labels_every_frame_and_bad_values_name_the_option(ctx, runner):
    from app.models import Annotation

    base = ["egonet", "demo", "--frames-per-activity", "2", "--width", "64", "--height", "48", "--no-train"]
    for bad in ("1.5", "-0.25", "nan"):
        result = runner.invoke(args=[*base, "--unlabelled-fraction", bad])
        assert result.exit_code == 1, (bad, result.output)
        assert "Error: --unlabelled-fraction must be between 0 and 1" in result.output
    assert db.session.execute(db.select(Frame)).first() is None  # refused before anything was added
    result = runner.invoke(args=[*base, "--unlabelled-fraction", "0"])
    assert result.exit_code == 0, result.output
    assert "14 frames added" in result.output and "0 of the new frames are left to label" in result.output
    assert len(db.session.execute(db.select(Annotation)).all()) == 14


@pytest.mark.slow
@pytest.mark.one_database
def test_the_demo_leaves_a_trained_quick_start_run_that_suggest_uses(ctx, runner):
    """About 20 s: the quick-start run trains on 14 frames."""
    from app.models.training import RunStatus, TrainingRun
    from app.services import labelling

    args = ["egonet", "demo", "--frames-per-activity", "3", "--width", "64", "--height", "48"]
    result = runner.invoke(args=args)
    assert result.exit_code == 0, result.output
    assert "demo: training 'demo quick start (egonet-lite)' for Suggest" in result.output
    run = db.session.execute(db.select(TrainingRun)).scalar_one()
    assert (run.name, run.status, run.model_name, run.epochs) == ("demo quick start (egonet-lite)", RunStatus.DONE, "egonet-lite", 6)
    assert (run.config["train"]["width"], run.config["train"]["height"], run.config["train"]["lr"]) == (96, 72, 0.05)
    assert f"run {run.id} (demo quick start (egonet-lite)): done" in result.output
    unlabelled = db.session.execute(db.select(Frame).where(~Frame.annotations.any())).scalars().first()
    assert labelling.source_choices(unlabelled)["hint"] == f"Auto uses run {run.id}: trained on the demo's rendered frames like this one."
    again = runner.invoke(args=args)
    assert f"demo: the quick-start run {run.id} is there already" in again.output
    assert db.session.execute(db.select(db.func.count(TrainingRun.id))).scalar_one() == 1


def test_demo_frames_match_the_renderer(ctx, runner):
    from app.services import media
    from egonet import io, synth

    runner.invoke(args=["egonet", "demo", "--frames-per-activity", "1", "--width", "64", "--height", "48", "--no-train"])
    frame = db.session.execute(db.select(Frame).filter_by(source_name="cooking-0-0000")).scalar_one()
    expected = synth.render_frame("cooking", 0, seed=0, width=64, height=48)
    np.testing.assert_array_equal(io.read_image(media.local_path(frame.rgb_path)), expected.rgb)
