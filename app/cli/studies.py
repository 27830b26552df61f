"""Human-study commands: create a study from a definition file, show one, precompute superpixels, export results."""

import json
from pathlib import Path

import click

from app.cli.group import bp, progress_bar

MAX_DEFINITION_BYTES = 1024 * 1024


def _study(study_id: int):
    from app.extensions import db
    from app.models.studies import Study

    study = db.session.get(Study, study_id)
    if study is None:
        raise click.ClickException(f"no study with id {study_id}")
    return study


def _base(base_url: str | None) -> str:
    """The links' start: ``--base-url``, else the ``PUBLIC_URL`` setting, else nothing (the links are paths)."""
    from flask import current_app

    return (base_url or current_app.config.get("PUBLIC_URL") or "").rstrip("/")


def _open_link(study, base_url: str | None) -> str | None:
    return f"{_base(base_url)}/s/o/{study.open_link_token}" if study.open_link_token else None


BASE_URL = click.option(
    "--base-url",
    default=None,
    help="The site's address for the links, e.g. https://studies.example.org [default: the PUBLIC_URL setting, else paths only].",
)


@bp.cli.command("study-create")
@click.argument("file", type=click.Path(dir_okay=False, exists=True, path_type=Path))
@BASE_URL
def study_create_command(file, base_url):
    """Create a study from the definition FILE (JSON; the builder's definition.json download).

    Prints {"id": ..., "open_link": "..."} as JSON (open_link is null without
    one). An unknown key or a bad value is a one-line error naming the key,
    and nothing is created.
    """
    from app.services.studies import study_from_definition
    from egonet.io import decode_json

    data = file.read_bytes()
    if len(data) > MAX_DEFINITION_BYTES:
        raise click.ClickException(f"{file}: a definition file has at most 1 MiB")
    try:
        doc = decode_json(data)
    except ValueError as exc:
        raise click.ClickException(f"{file}: not valid JSON ({exc})") from None
    study = study_from_definition(doc)
    click.echo(json.dumps({"id": study.id, "open_link": _open_link(study, base_url)}))


@bp.cli.command("study-show")
@click.argument("study_id", type=int)
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True)
@BASE_URL
def study_show_command(study_id, fmt, base_url):
    """Show study STUDY_ID: its settings (as a definition file), links and participants.

    Each participant comes with their external id, status, condition and
    whether they passed the checks.
    """
    from app.services import studies

    study = _study(study_id)
    studies.close_overdue([p.id for p in study.participants])
    results = studies.checks_of(study.participants)
    people = [
        {
            "participant": p.label,
            "code": studies.format_code(p.code),
            "entry": p.entry.value,
            "platform": p.platform,
            "external_id": p.external_id,
            "status": studies.progress(p).status,
            "condition": studies.condition_name(p),
            "checks_passed": results[p.id].passed,
            "completion_code": p.completion_code,
            "link": f"{_base(base_url)}/s/l/{p.link_token}" if p.link_token and p.link_used_at is None else None,
        }
        for p in study.participants
    ]
    doc = {
        "id": study.id,
        "status": study.status.value,
        "open_link": _open_link(study, base_url),
        "places": studies.places_taken(study),
        "settings": studies.definition_of(study),
        "participants": people,
    }
    if fmt == "json":
        click.echo(json.dumps(doc, indent=1))
        return
    click.echo(f"study {study.id}: {study.name} ({doc['status']}), {doc['places']} places taken{f' of {study.cap}' if study.cap else ''}")
    click.echo(f"open link: {doc['open_link'] or 'none'}")
    for person in people:
        checks = {True: "passed", False: "FAILED", None: "-"}[person["checks_passed"]]
        click.echo(
            f"  {person['participant']}  {person['code']}  {person['external_id'] or '-':24}  {person['condition'] or '-':12}"
            f"  {person['status']:12}  checks {checks}"
        )


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
    cached = len(study.frames) - computed
    click.echo(f"study {study.id}: {computed} frame{'s' if computed != 1 else ''} computed, {cached} already cached")


@bp.cli.command("study-export")
@click.argument("study_id", type=int)
@click.option("--out", "out", type=click.Path(file_okay=False, path_type=Path), required=True, help="Folder to write into (created if needed).")
def study_export_command(study_id, out):
    """Export study STUDY_ID: trials, clicks, events and participants as CSV, everything as JSON, soft masks as PNGs.

    Writes trials.csv, clicks.csv, events.csv, participants.csv, study.json,
    definition.json and masks/ (16-bit PNGs, value x 65535:
    masks/P01/0001-frame12.png per answered trial, masks/mean/frame12.png
    per frame, masks/manifest.csv).
    """
    from app.services.studies import export_to_folder

    study = _study(study_id)
    with progress_bar("Exporting") as (on_start, on_progress):
        try:
            written = export_to_folder(study, out, on_start=on_start, on_progress=on_progress)
        except OSError as exc:
            raise click.ClickException(f"{out}: cannot write ({exc.strerror or exc})") from None
    click.echo(f"study {study.id}: {len(written)} files written to {out}")
