"""Scoring commands (score)."""

import sys

import click

from app.cli import bp, progress_bar

FORMATS = {"table": "to_table", "csv": "to_csv", "latex": "to_latex", "json": "to_json"}


def _ids(ctx, param, value: str | None) -> list[int] | None:
    """``"3,5"`` -> [3, 5]; an empty string -> [] (none); not given -> None (all)."""
    if value is None:
        return None
    try:
        return [int(part) for part in value.split(",") if part.strip()]
    except ValueError:
        raise click.BadParameter("give ids separated by commas, e.g. 3,5") from None


@bp.cli.command("score")
@click.option("--runs", callback=_ids, help="Training run ids, comma-separated ('' for none) [default: every completed run].")
@click.option("--studies", callback=_ids, help="Study ids, comma-separated ('' for none) [default: every study].")
@click.option("--format", "fmt", type=click.Choice(list(FORMATS)), default="table", show_default=True)
@click.option("--baselines/--no-baselines", default=True, show_default=True, help="Include AOP, the centre prior and saliency.")
@click.option("--thresholds", type=click.IntRange(min=1, max=10_000), default=99, show_default=True, help="Number T of thresholds k/(T+1).")
@click.option("--per-image", is_flag=True, help="Average precision and recall over frames instead of pooling pixel counts.")
@click.option("--no-cache", is_flag=True, help="Score again instead of reading cached statistics.")
@click.option("--exclude-failed-checks", is_flag=True, help="Leave out participants who failed a comprehension or attention check.")
@click.option("--by-condition", is_flag=True, help="Split the participants' rows by the studies' conditions.")
def score_command(runs, studies, fmt, baselines, thresholds, per_image, no_cache, exclude_failed_checks, by_condition):
    """Print the score table: MF and AP per activity for models, baselines and people.

    Rows are the completed training runs (held-out frames), the baselines
    (every labelled frame; AOP fitted per leave-one-activity-out fold) and
    each participant of the studies (the frames they answered; MF only).
    The mean column is the unweighted mean of the per-activity values.
    """
    from app.services.scoring import build_report

    with progress_bar("Scoring frames", file=sys.stderr) as (on_start, on_progress):
        report = build_report(
            run_ids=runs,
            study_ids=studies,
            baselines=baselines,
            thresholds=thresholds,
            per_image=per_image,
            use_cache=not no_cache,
            on_start=on_start,
            on_progress=on_progress,
            exclude_failed_checks=exclude_failed_checks,
            by_condition=by_condition,
        )
    click.echo(getattr(report, FORMATS[fmt])(), nl=False)
