"""Labelling commands: export masks, import them back."""

from pathlib import Path

import click

from app.cli import bp, progress_bar
from app.models import Status

STATUS_CHOICES = click.Choice([s.value for s in Status])


@bp.cli.command("export")
@click.option("--out", type=click.Path(path_type=Path), required=True, help="New (or empty) folder to write.")
@click.option("--format", "fmt", type=click.Choice(["png", "coco", "both"]), default="both", show_default=True)
@click.option("--activity", "activities", multiple=True, help="Only this activity (repeat for several) [default: all].")
@click.option(
    "--status",
    "statuses",
    type=STATUS_CHOICES,
    multiple=True,
    help="Export annotations with this status (repeat for several) [default: done and reviewed].",
)
def export_command(out, fmt, activities, statuses):
    """Export action-object masks: masks/<activity>/<sequence>/<frame>.png
    (binary, the union of the frame's instances) and annotations.json (COCO,
    one RLE mask per instance)."""
    from app.services.exchange import DEFAULT_STATUSES, export_folder

    with progress_bar("Exporting") as (on_start, on_progress):
        report = export_folder(
            out,
            fmt=fmt,
            activities=list(activities),
            statuses=[Status(s) for s in statuses] or list(DEFAULT_STATUSES),
            on_start=on_start,
            on_progress=on_progress,
        )
    click.echo(f"{out}: {report.frames} frames, {report.instances} action-objects exported")


@bp.cli.command("import-annotations")
@click.argument("path", type=click.Path(path_type=Path))
@click.option("--author", help="Author of the imported annotations [default: as recorded; 'import' for PNG masks].")
@click.option("--status", type=STATUS_CHOICES, help="Status to give them [default: as recorded; done for PNG masks].")
@click.option("--replace", is_flag=True, help="Overwrite the author's existing annotation of a frame.")
@click.option("--skip-missing", is_flag=True, help="Skip masks of frames that are not in the database.")
def import_annotations_command(path, author, status, replace, skip_missing):
    """Import masks from an export (folder or zip from `flask egonet export` or
    the download button), a COCO JSON file, or a folder of PNG masks laid out
    as <activity>/<sequence>/<frame>.png. The frames must be imported first."""
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
