"""Human-study commands: precompute superpixels, export results."""

from pathlib import Path

import click

from app.cli import bp, progress_bar


def _study(study_id: int):
    from app.extensions import db
    from app.models.studies import Study

    study = db.session.get(Study, study_id)
    if study is None:
        raise click.ClickException(f"no study with id {study_id}")
    return study


@bp.cli.command("study-superpixels")
@click.argument("study_id", type=int)
def study_superpixels_command(study_id):
    """Compute and cache the superpixels of every frame of study STUDY_ID.

    Soft masks need them; computing them ahead spares the first views and
    exports (about a second per 1280x960 frame).
    """
    from app.services.studies import precompute_superpixels

    study = _study(study_id)
    with progress_bar("Superpixels") as (on_start, on_progress):
        on_start(len(study.frames))
        computed = precompute_superpixels(study, on_progress=on_progress)
    click.echo(f"study {study.id}: {computed} frames computed, {len(study.frames) - computed} already cached")


@bp.cli.command("study-export")
@click.argument("study_id", type=int)
@click.option("--out", "out", type=click.Path(file_okay=False, path_type=Path), required=True, help="Folder to write into (created if needed).")
def study_export_command(study_id, out):
    """Export study STUDY_ID: trials, clicks and events as CSV, everything as JSON, soft masks as PNGs.

    Writes trials.csv, clicks.csv, events.csv, study.json and masks/ (16-bit
    PNGs, value x 65535: masks/P01/0001-frame12.png per answered trial,
    masks/mean/frame12.png per frame, masks/manifest.csv).
    """
    from app.services.studies import export_to_folder

    study = _study(study_id)
    with progress_bar("Exporting") as (on_start, on_progress):
        try:
            written = export_to_folder(study, out, on_start=on_start, on_progress=on_progress)
        except OSError as exc:
            raise click.ClickException(f"{out}: cannot write ({exc.strerror or exc})") from None
    click.echo(f"study {study.id}: {len(written)} files written to {out}")
