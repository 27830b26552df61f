"""Labelling commands: export masks, import them back, a trained run's proposals."""

from pathlib import Path

import click

from app.cli.group import bp, progress_bar
from app.models import Status

STATUS_CHOICES = click.Choice([s.value for s in Status])
EXPORT_STATUS_CHOICES = click.Choice([s.value for s in Status if s is not Status.TODO])


@bp.cli.command("export")
@click.option("--out", required=True, help="New (or empty) folder to write, or s3://bucket/prefix/name.")
@click.option("--format", "fmt", type=click.Choice(["png", "coco", "both"]), default="both", show_default=True)
@click.option("--images", is_flag=True, help="Also copy each exported frame's RGB file into images/.")
@click.option("--activity", "activities", multiple=True, help="Only this activity (repeat for several) [default: all].")
@click.option(
    "--status",
    "statuses",
    type=EXPORT_STATUS_CHOICES,
    multiple=True,
    help="Export annotations with this status (repeat for several) [default: done and reviewed].",
)
@click.option("--annotator", "annotators", multiple=True,
              help="Only this user's annotations (repeat for several) [default: everyone's].")
def export_command(out, fmt, images, activities, statuses, annotators):
    """Export every annotation that passes the filters: masks/<activity>/<sequence>/<frame>.png
    (the frame's mask: its best annotation's union), annotators/<user>/... (each
    annotation's union), annotations.json (COCO, one RLE mask per instance, with
    its annotator and status) and, with --images, images/ (the RGB files)."""
    from app.services.exchange import DEFAULT_STATUSES, ExportOptions, export_folder

    options = ExportOptions.of(fmt=fmt, images=images, activities=activities, statuses=statuses or DEFAULT_STATUSES,
                               annotators=annotators)
    with progress_bar("Exporting") as (on_start, on_progress):
        report = export_folder(out, options, on_start=on_start, on_progress=on_progress)
    click.echo(f"{out}: {report.summary()}")


@bp.cli.command("import-annotations")
@click.argument("path", type=click.Path(path_type=Path))
@click.option("--author", help="Author of the imported annotations [default: as recorded; 'import' for PNG masks].")
@click.option("--status", type=STATUS_CHOICES, help="Status to give them [default: as recorded; done for PNG masks].")
@click.option("--replace", is_flag=True, help="Overwrite the author's existing annotation of a frame.")
@click.option("--skip-missing", is_flag=True, help="Skip masks of frames that are not in the database.")
def import_annotations_command(path, author, status, replace, skip_missing):
    """Import masks from an export (folder or zip from `flask egonet export` or
    the Label page: every annotator's annotations), a COCO JSON file, or a folder
    of PNG masks laid out as <activity>/<sequence>/<frame>.png. The frames must
    be imported first."""
    from app.services.exchange import import_annotations

    with progress_bar("Importing") as (on_start, on_progress):
        report = import_annotations(
            path,
            author=author,
            status=Status(status) if status else None,
            replace=replace,
            skip_missing=skip_missing,
            on_start=on_start,
            on_progress=on_progress,
        )
    line = f"{path}: {report.annotations} annotations ({report.instances} action-objects) imported"
    line += f", {report.skipped} kept as they were" if report.skipped else ""
    line += f", {report.missing} without a frame skipped" if report.missing else ""
    click.echo(line)


@bp.cli.command("suggest")
@click.option("--source", type=click.Choice(["auto", "model", "depth", "handled", "saliency"]), default="auto",
              show_default=True, help="Who proposes: auto is a run trained on frames like each one (the demo's rendered "
              "frames, or real ones), else depth, else handled; model a trained run; depth, handled and saliency "
              "need no run.")
@click.option("--run", "run_id", type=int, help="The training run that proposes [default: the latest finished one].")
@click.option("--frames", help="Comma-separated frame ids.")
@click.option("--activity", "activities", multiple=True, help="The frames of this activity (repeatable).")
@click.option("--user", "username", required=True, help="Whose in-progress annotations the proposals join (an annotator or admin).")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto", show_default=True)
@click.option("--queue", is_flag=True, help="Queue the job for `flask egonet worker`.")
def suggest_command(source, run_id, frames, activities, username, device, queue):
    """Propose the action-objects of frames still to label (all of them
    unless --frames/--activity say which): each becomes an instance of the
    user's annotation, marked with its source until accepted or edited on
    the labelling page. Frames labelled already, or being labelled by
    someone else, are skipped."""
    from app.services.labelling import queue_suggestions, resolve_run, suggest_frames
    from app.services.labelling.suggest import batch_frames, labelling_user
    from app.services.training import frames_for_prediction

    try:
        frame_ids = [int(x) for x in frames.split(",") if x.strip()] if frames else []
    except ValueError:
        raise click.BadParameter("give frame ids separated by commas, e.g. 3,4,10", param_hint="--frames") from None
    if run_id is not None and source not in ("auto", "model"):
        raise click.BadParameter(f"a run proposes as the model source, not {source}", param_hint="--run")
    user = labelling_user(username)
    if run_id is not None or source == "model":
        run_id = resolve_run(run_id).id  # a bad run stops here, before any frame
    what = f"run {run_id}" if run_id is not None else source
    chosen = frames_for_prediction(activity_names=activities, frame_ids=frame_ids)
    if queue:
        todo, skipped = batch_frames(chosen, user)
        queue_suggestions(todo, user, run_id=run_id, source=source, device=device)
        click.echo(f"{len(todo)} frames queued for proposals by {what} to {user.username}"
                   f"{f' ({len(skipped)} labelled or taken skipped)' if skipped else ''}: start `flask egonet worker`")
        return
    with progress_bar("Suggesting") as (on_start, on_progress):
        on_start(len(chosen))
        report = suggest_frames(chosen, user, run_id=run_id, source=source, device=device, on_progress=on_progress)
    for suggestion in report.suggestions:
        click.echo(f"frame {suggestion.frame_id}: {suggestion.summary()}")
    for frame_id, why in report.skipped:
        click.echo(f"frame {frame_id}: skipped, {why}")
    click.echo(f"{what}: {report.proposals} proposals on {len(report.suggestions)} frames for {user.username}, "
               f"{len(report.skipped)} frames skipped")


@bp.cli.group("classes")
def classes_group():
    """The project's object classes: the names the labelling page's label field completes from."""


@classes_group.command("list")
def classes_list_command():
    """Print the class names, one a line (alphabetical)."""
    from app.services.labelling.classes import class_names

    for name in class_names():
        click.echo(name)


@classes_group.command("add")
@click.argument("names", nargs=-1, required=True)
def classes_add_command(names):
    """Add class names (a name already in the list, in any case, is left as it is)."""
    from app.services.labelling.classes import add_classes

    added = add_classes(names)
    click.echo(f"added {len(added)} of {len(names)}: {', '.join(added) or 'none new'}")


@classes_group.command("remove")
@click.argument("name")
def classes_remove_command(name):
    """Take a class name off the list (saved labels keep it)."""
    from app.services.labelling.classes import remove_class

    remove_class(name)
    click.echo(f"removed {name.strip()}")
