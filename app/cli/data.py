"""Data commands: import, demo, create-user."""

from pathlib import Path

import click

from app.cli.group import bp, progress_bar
from app.models import Role, Status


@bp.cli.command("import")
@click.argument("path")
@click.option("--activity", required=True, help="Activity the frames belong to (created if new).")
@click.option("--sequence", help="Recording name within the activity [default: the folder or video name].")
@click.option("--stride", type=click.IntRange(min=1), default=1, show_default=True, help="Keep every N-th frame.")
@click.option("--depth", "depth_dir", type=click.Path(path_type=Path), help="Folder of depth maps (16-bit PNG mm, .npy/.npz m).")
@click.option("--dhg", "dhg_dir", type=click.Path(path_type=Path), help="Folder of DHG images (3-channel 8-bit: gray, height, depth, as the authors' files).")
@click.option("--masks", "masks_dir", type=click.Path(path_type=Path), help="Folder of binary mask PNGs (initial annotations).")
@click.option("--intrinsics", type=click.Path(path_type=Path), help="Camera intrinsics JSON (fx, fy, cx, cy or a 3x3 matrix).")
@click.option("--depth-source", type=click.Choice(["measured", "predicted"]), default="measured", show_default=True,
              help="predicted: the depth (or DHG) was estimated from the RGB by some network, and is marked so.")
@click.option("--mask-author", default="import", show_default=True, help="Author of imported masks.")
@click.option(
    "--mask-status",
    type=click.Choice([s.value for s in Status]),
    default=Status.DONE.value,
    show_default=True,
    help="Status of imported masks.",
)
def import_command(path, activity, sequence, stride, depth_dir, dhg_dir, masks_dir, intrinsics, depth_source, mask_author,
                   mask_status):
    """Import frames from PATH: a folder of images, a zip of one, or a video file; in a bucket too
    (s3://bucket/prefix/recording, with the AWS_* variables as for STORAGE_URL).

    A folder may hold the images directly or in rgb/ (or color/), with
    depth/, dhg/ and masks/ beside them, matched by file stem, and one
    intrinsics *.json. Re-importing the same files adds nothing.
    """
    from app.services.importing import import_path

    with progress_bar("Importing") as (on_start, on_progress):
        report = import_path(
            path,
            activity=activity,
            sequence=sequence,
            stride=stride,
            depth_dir=depth_dir,
            dhg_dir=dhg_dir,
            masks_dir=masks_dir,
            intrinsics=intrinsics,
            depth_source=depth_source,
            mask_author=mask_author,
            mask_status=Status(mask_status),
            on_start=on_start,
            on_progress=on_progress,
        )
    click.echo(f"{report.activity} / {report.sequence}: {report.summary()}")


@bp.cli.command("import-points")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--activity", required=True, help="The activity whose frames the points are for (imported already).")
@click.option("--sigma", type=float, help="The Gaussian's standard deviation in the frames' pixels "
              "[default: the click study's 60 px at 1280 px wide, scaled to each frame].")
@click.option("--author", default="import", show_default=True, help="Author of the ground-truth annotations.")
def import_points_command(file, activity, sigma, author):
    """Make each frame's ground truth from attention points (the paper's Table 4).

    FILE is a CSV with the header frame,x,y: the frame's file stem, then the
    point in its pixels (x = column, y = row); several rows per frame are
    allowed. Each frame's mask is a Gaussian around its points binarised
    within one sigma; a frame without a row has no action-object. Importing
    again replaces the author's earlier points. A bad row stops the import,
    naming its line, and nothing is kept.
    """
    from app.services.attention_points import import_points

    click.echo(import_points(file, activity=activity, sigma=sigma, author=author).summary())


QUICK_START = {
    "model": "egonet-lite", "folds": "single", "epochs": 6, "size": (96, 72), "lr": 0.05,
    "name": "demo quick start (egonet-lite)",
}
"""The demo's run: small enough to train in about a minute of CPU on one thread (max-F 0.54 on its
42 held-out frames, where the action-object prior has 0.45), trained once."""


@bp.cli.command("demo")
@click.option("--frames-per-activity", type=click.IntRange(min=1), default=40, show_default=True)
@click.option(
    "--unlabelled-fraction",
    type=float,
    default=0.25,
    show_default=True,
    help="Share of each activity's frames (the last ones) left without an annotation, for you to label; 0 labels every frame.",
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--width", type=click.IntRange(min=32, max=4096), default=320, show_default=True)
@click.option("--height", type=click.IntRange(min=32, max=4096), default=240, show_default=True)
@click.option("--train/--no-train", default=True, show_default=True,
              help=f"Then train the quick-start run {QUICK_START['name']!r} (about a minute on a CPU), "
              "so Suggest's learned proposals exist at once.")
@click.pass_context
def demo_command(ctx, frames_per_activity, unlabelled_fraction, seed, width, height, train):
    """Create the demo dataset: synthetic RGB-D frames for the seven activities.

    Every frame gets its ground truth as a reviewed annotation, except the
    last --unlabelled-fraction of each activity (a quarter by default),
    which are left for you to label. Then (unless --no-train) a small
    egonet-lite run trains on the labelled frames, as `flask egonet train`
    would with the options in QUICK_START.
    """
    from app.services.demo import create_demo

    with progress_bar("Rendering demo") as (on_start, on_progress):
        reports = create_demo(
            frames_per_activity=frames_per_activity,
            unlabelled_fraction=unlabelled_fraction,
            seed=seed,
            width=width,
            height=height,
            on_start=on_start,
            on_progress=on_progress,
        )
    added = sum(r.added for r in reports)
    skipped = sum(r.skipped for r in reports)
    left = sum(r.added - r.annotations for r in reports)
    click.echo(
        f"demo: {added} frames added, {skipped} already present, in {len(reports)} activities; "
        f"{left} of the new frames are left to label"
    )
    if train:
        _train_quick_start(ctx)


def _train_quick_start(ctx: click.Context) -> None:
    """Train the quick-start run with ``flask egonet train``'s own code, unless it is there already."""
    import torch

    from app.cli.training import train_command
    from app.extensions import db
    from app.models.training import RunStatus, TrainingRun
    from app.services.training import TrainingProblem

    done = db.session.execute(
        db.select(TrainingRun.id).filter_by(name=QUICK_START["name"], status=RunStatus.DONE).limit(1)
    ).scalar_one_or_none()
    if done is not None:
        click.echo(f"demo: the quick-start run {done} is there already")
        return
    click.echo(f"demo: training {QUICK_START['name']!r} for Suggest (about a minute on a CPU; --no-train skips it)")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny inputs: more threads only wait on each other
    try:
        ctx.invoke(train_command, **QUICK_START)
    except TrainingProblem as exc:
        click.echo(f"demo: no quick-start run: {exc.message}")
    finally:
        torch.set_num_threads(threads)


@bp.cli.command("create-user")
@click.argument("name")
@click.option("--role", type=click.Choice([r.value for r in Role]), help="Role of the new user (required unless NAME exists).")
@click.option("--password", help="Password (prompted when omitted and a terminal is attached; generated otherwise).")
@click.option("--if-missing", is_flag=True, help="Do nothing (and succeed) when the user already exists.")
@click.option("--reset-password", is_flag=True, help="When the user already exists, give them a new password (ending their sessions).")
def create_user_command(name, role, password, if_missing, reset_password):
    """Create a user NAME with a role (or, with --reset-password, renew an existing user's password).

    A generated password is printed once. Passwords need at least 10
    characters and must not be easy to guess.
    """
    from app.cli.users import ask_password
    from app.services.users import create_user, find_user, set_password

    if if_missing and reset_password:
        raise click.UsageError("--if-missing keeps an existing user, --reset-password changes it: give one of them")
    existing = find_user(name)
    if existing is not None and if_missing:
        click.echo(f"user {name!r} exists already; keeping it")
        return
    if existing is not None and reset_password:
        if role is not None and role != existing.role.value:
            raise click.ClickException(f"{existing.username!r} is {existing.role.value}, not {role}; change roles with set-role")
        generated = set_password(existing, password or ask_password(existing.role))
        click.echo(f"new password for {existing.role.value} {existing.username!r}; their sessions have ended")
        if generated:
            click.echo(f"password: {generated}")
        return
    if role is None:
        raise click.UsageError("Missing option '--role' (NAME is a new user).")
    user, generated = create_user(name, role, password or ask_password(Role(role)))
    click.echo(f"created {user.role.value} {user.username!r}")
    if generated:
        click.echo(f"password: {generated}")


@bp.cli.command("media-check")
@click.option("--remove-orphans", is_flag=True, help="Delete media no row refers to (older than --grace).")
@click.option("--grace", type=click.FloatRange(min=0), default=3600.0, show_default=True, help="Seconds an orphan must be old to be removed.")
def media_check_command(remove_orphans, grace):
    """Check that every referenced media file exists, and find orphans (left by a crash)."""
    from app.services import media

    report = media.check(remove_orphans=remove_orphans, grace_s=grace)
    click.echo(
        f"{report.files} files, {report.referenced} referenced, {len(report.missing)} missing, "
        f"{len(report.orphans)} orphaned, {len(report.removed)} removed"
    )
    for rel in report.missing:
        click.echo(f"missing: {rel}", err=True)
    if report.missing:
        raise click.ClickException(f"{len(report.missing)} referenced media files are missing")


@bp.cli.command("storage-migrate")
@click.option("--to", "url", required=True, metavar="URL", help="The folder or s3://bucket/prefix to copy the site's files into.")
@click.option("--check-only", is_flag=True, help="Copy nothing; check that URL holds every file, equal.")
def storage_migrate_command(url, check_only):
    """Copy every file of STORAGE_URL (media/, checkpoints/, exports/) to URL and check each copy.

    Files already there and equal are kept, so it can run again after a failure
    or while the site runs; then set STORAGE_URL=URL and restart every host.
    """
    from app.services import storage

    try:
        target = storage.open_url(url)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--to") from None
    with progress_bar("Checking" if check_only else "Copying") as (on_start, on_progress):
        report = storage.migrate(target, check_only=check_only, on_start=on_start, on_progress=on_progress)
    done = f"{report.present} present and equal, {len(report.bad)} missing or different" if check_only else \
        f"{report.copied} copied, {report.present} there already"
    click.echo(f"{url}: {report.files} files ({report.bytes / 1e6:.1f} MB): {done}")
    for key in report.bad:
        click.echo(f"missing or different: {key}", err=True)
    if report.bad:
        raise click.ClickException(f"{len(report.bad)} files are missing or different in {url}")


@bp.cli.command("export-3d")
@click.argument("frame_id", type=int, metavar="FRAME")
@click.option("--out", "out", type=click.Path(dir_okay=False, path_type=Path), help="The .ply file [default: frame-<id>.ply].")
@click.option("--prediction", "prediction_id", type=int, help="Prediction to mark [default: the frame's latest].")
@click.option("--max-points", type=click.IntRange(min=1), default=1_000_000, show_default=True)
def export_3d_command(frame_id, out, prediction_id, max_points):
    """Write frame FRAME as a coloured PLY point cloud (depth + intrinsics), the action-object marked.

    Labelled points are tinted green, predicted ones red, both yellow; the
    vertices also carry `truth` and `predicted` properties.
    """
    from app.extensions import db
    from app.models import Frame
    from app.services.pointcloud import export_ply

    frame = db.session.get(Frame, frame_id)
    if frame is None:
        raise click.ClickException(f"no frame with id {frame_id}")
    out = out or Path(f"frame-{frame_id}.ply")
    made = export_ply(frame, out, prediction_id=prediction_id, max_points=max_points)
    cloud = made.cloud
    predicted = f"{int(cloud.predicted.sum())} predicted (prediction {made.prediction.id}, p >= {made.threshold:.3f})" \
        if made.prediction is not None else "no prediction"
    labelled = f"{int(cloud.truth.sum())} labelled" if made.has_truth else "no ground truth"
    click.echo(f"{out}: {len(cloud)} points (every {cloud.stride}. pixel), {labelled}, {predicted}")
