"""Scoring commands (score)."""

import sys

import click

from app.cli.group import bp, progress_bar

FORMATS = {"table": "to_table", "csv": "to_csv", "latex": "to_latex", "json": "to_json"}
METRICS = ("pooled", "per-image", "ods-ois")


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
@click.option("--baselines/--no-baselines", default=True, show_default=True, help="Include the baselines (AOP, centre prior, saliency, GBVS, handled + viewed object).")
@click.option(
    "--metric",
    type=click.Choice(METRICS),
    default="pooled",
    show_default=True,
    help="pooled: counts summed over an activity's frames; per-image: mean of each frame's best F; ods-ois: BSDS ODS, OIS and AP.",
)
@click.option(
    "--frames",
    type=click.Choice(["shared", "each"]),
    default="shared",
    show_default=True,
    help="shared: each activity on the frames every row has there; each: every row on all its frames.",
)
@click.option("--answered-only", is_flag=True, help="Leave out people's unanswered trials (else each counts as an empty map).")
@click.option("--compare", nargs=2, metavar="KEY_A KEY_B", help="Print A minus B (row keys as in the JSON's key) with a paired test instead of the table.")
@click.option("--resamples", type=click.IntRange(min=0, max=100_000), default=1000, show_default=True, help="Bootstrap resamples (0: no intervals).")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Seed of the bootstrap.")
@click.option("--thresholds", type=click.IntRange(min=1, max=10_000), default=99, show_default=True, help="Number T of thresholds k/(T+1).")
@click.option("--no-cache", is_flag=True, help="Score again instead of reading cached statistics.")
@click.option("--exclude-failed-checks", is_flag=True, help="Leave out participants who failed a comprehension or attention check.")
@click.option("--by-condition", is_flag=True, help="Split the participants' rows by the studies' conditions.")
def score_command(
    runs, studies, fmt, baselines, metric, frames, answered_only, compare, resamples, seed, thresholds, no_cache,
    exclude_failed_checks, by_condition,
):
    """Print the score table: per activity and their mean, for models, baselines and people.

    Rows are the completed training runs (held-out frames; runs that differ
    only in their seed also as one row with the mean and standard deviation),
    the baselines (every labelled frame; AOP fitted per leave-one-activity-out
    fold) and each participant of the studies (the frames of their trials; MF
    only). Every cell has its number of frames and a 95% bootstrap interval.
    The mean column is the unweighted mean of the per-activity values.
    """
    from app.services.scoring import build_report

    if compare and fmt not in ("table", "json"):
        raise click.UsageError("--compare prints a table or JSON (--format table|json)")
    with progress_bar("Scoring frames", file=sys.stderr) as (on_start, on_progress):
        report = build_report(
            run_ids=runs,
            study_ids=studies,
            baselines=baselines,
            metric=metric,
            frames=frames,
            answered_only=answered_only,
            resamples=resamples,
            seed=seed,
            thresholds=thresholds,
            compare_keys=tuple(compare) if compare else None,
            use_cache=not no_cache,
            on_start=on_start,
            on_progress=on_progress,
            exclude_failed_checks=exclude_failed_checks,
            by_condition=by_condition,
        )
    if report.comparison is not None:
        click.echo(report.comparison.to_json() if fmt == "json" else report.comparison.to_text(), nl=False)
        return
    click.echo(getattr(report, FORMATS[fmt])(), nl=False)
