"""Scoring commands: ``score`` (the table or a comparison) and ``report`` (how it was made, or a methods paragraph)."""

import sys
from pathlib import Path

import click

from app.cli.group import bp, progress_bar
from egonet.metrics import DEFAULT_EMPTY, DEFAULT_RESAMPLES, EMPTY_POLICIES, MAX_RESAMPLES, METRIC_ALIASES, METRICS

FORMATS = {"table": "to_table", "csv": "to_csv", "latex": "to_latex", "json": "to_json"}


def _ids(ctx, param, value: str | None) -> list[int] | None:
    """``"3,5"`` -> [3, 5]; an empty string -> [] (none); not given -> None (all)."""
    if value is None:
        return None
    try:
        return [int(part) for part in value.split(",") if part.strip()]
    except ValueError:
        raise click.BadParameter("give ids separated by commas, e.g. 3,5") from None


def _metric(ctx, param, value: str) -> str:
    """The convention's name; an old one says so on stderr (stdout may be data)."""
    if value in METRIC_ALIASES:
        click.echo(f"--metric {value} is deprecated and goes in the next release: use --metric {METRIC_ALIASES[value]}", err=True)
        return METRIC_ALIASES[value]
    return value


# The options that say what to score and how, shared by `score` and `report` (applied in this order).
REPORT_OPTIONS = (
    click.option("--runs", callback=_ids, help="Training run ids, comma-separated ('' for none) [default: every completed run]."),
    click.option("--trained-on", "trained_on", multiple=True, metavar="ACTIVITY",
                 help="The table's training set (repeat the option): the runs trained on every frame of exactly these "
                      "activities (train --folds all), the learned baselines fitted on them, scored on the other "
                      "activities (the paper's Tables 3 and 4) [default: leave-one-activity-out, Table 2; or the "
                      "training set of the --runs chosen]."),
    click.option("--columns", type=click.Choice(["activities", "sequences"]), default="activities", show_default=True,
                 help="The table's columns: activities, or each activity's recordings (sequences) as 'activity / sequence', "
                      "e.g. a dataset's videos imported as one activity (Tables 3 and 4)."),
    click.option("--studies", callback=_ids, help="Study ids, comma-separated ('' for none) [default: every study]."),
    click.option("--baselines/--no-baselines", default=True, show_default=True,
                 help="Include the baselines: Table 2's Judd, GBVS, Handled+Viewed-Obj, AOP, FP-MCG and salObj+depth "
                      "(the learned ones fitted per leave-one-activity-out fold, here and now) and the centre prior "
                      "and saliency."),
    click.option("--metric", type=click.Choice([*METRICS, *METRIC_ALIASES]), default="pooled", show_default=True, callback=_metric,
                 help="pooled: counts summed over an activity's frames; ois-mean: mean of each frame's best F; mean-curve: "
                      "best F of the precision-recall curve averaged over frames; ods-ois: BSDS ODS, OIS and AP "
                      "(per-image: the old name of ois-mean)."),
    click.option("--frames", type=click.Choice(["shared", "each"]), default="shared", show_default=True,
                 help="shared: each activity on the frames every row has there; each: every row on all its frames "
                      "(the mode a human-study table needs: each person on the frames they saw)."),
    click.option("--empty-frames", "empty", type=click.Choice(EMPTY_POLICIES), default=DEFAULT_EMPTY, show_default=True,
                 help="How ois-mean and mean-curve count a frame without action-object pixels: leave it out, score it 0, "
                      "or 1 where the map predicts nothing at a threshold (one-if-empty)."),
    click.option("--answered-only", is_flag=True, help="Leave out people's unanswered trials (else each counts as an empty map)."),
    click.option("--resamples", type=click.IntRange(min=0, max=MAX_RESAMPLES), default=DEFAULT_RESAMPLES, show_default=True,
                 help="Bootstrap resamples B (0: no intervals); p-values below 1/(B+1) print as '< 0.001' and the like. "
                      "At most 33.5 million weights (resamples x frames): the error says how many fit."),
    click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Seed of the bootstrap."),
    click.option("--thresholds", type=click.IntRange(min=1, max=10_000), default=99, show_default=True, help="Number T of thresholds k/(T+1)."),
    click.option("--no-cache", is_flag=True, help="Score again instead of reading cached statistics."),
    click.option("--exclude-failed-checks", is_flag=True, help="Leave out participants who failed a comprehension or attention check."),
    click.option("--by-condition", is_flag=True, help="Split the participants' rows by the studies' conditions."),
)


def report_options(command):
    """Give a command the options of :data:`REPORT_OPTIONS`."""
    for option in reversed(REPORT_OPTIONS):
        command = option(command)
    return command


def _build_report(options: dict, compare: tuple[str, str] | None = None):
    from app.services.scoring import build_report

    options = dict(options)
    run_ids, study_ids, use_cache = options.pop("runs"), options.pop("studies"), not options.pop("no_cache")
    options["trained_on"] = list(options["trained_on"]) or None
    with progress_bar("Scoring frames", file=sys.stderr) as (on_start, on_progress):
        return build_report(run_ids=run_ids, study_ids=study_ids, use_cache=use_cache, compare_keys=compare,
                            on_start=on_start, on_progress=on_progress, **options)  # fmt: skip


@bp.cli.command("score")
@report_options
@click.option("--format", "fmt", type=click.Choice(list(FORMATS)), default="table", show_default=True)
@click.option("--compare", nargs=2, metavar="KEY_A KEY_B", help="Print A minus B (row keys as in the JSON's key) with a paired test instead of the table.")
def score_command(fmt, compare, **options):
    """Print the score table: per activity and their mean, for models, baselines and people.

    Rows are the completed training runs (held-out frames; runs that differ
    only in their seed also as one row with the mean and standard deviation),
    the baselines (every labelled frame; the learned ones, Judd, AOP, FP-MCG
    and salObj+depth, fitted per leave-one-activity-out fold: fitting them
    takes a while the first time, then they are cached) and each participant of the studies (the frames of their trials; MF
    only). With --trained-on A --trained-on B (Tables 3 and 4), the rows are
    the runs trained on every frame of A and B (--folds all), on the frames
    of other activities they predicted, and the baselines fitted on A and B. Every cell has its number of frames and a 95% bootstrap interval;
    every format says how the numbers were made (convention, thresholds,
    frames without action-object pixels, bootstrap, code version). The mean
    column is the unweighted mean of the per-activity values.
    """
    report = _build_report(options, tuple(compare) if compare else None)
    shown = report.comparison if report.comparison is not None else report
    method = "to_text" if shown is report.comparison and fmt == "table" else FORMATS[fmt]
    click.echo(getattr(shown, method)(), nl=False)


@bp.cli.command("report")
@report_options
@click.option("--methods", is_flag=True, help="Write a methods paragraph (plain English, the facts filled in) and the seed paper's BibTeX entry.")
@click.option("--out", "out_file", type=click.Path(dir_okay=False, writable=True, path_type=Path), help="Write to this file instead of stdout.")
def report_command(methods, out_file, **options):
    """Say how a score table is made: its facts, or with --methods a paragraph ready to paste into a paper.

    Takes the options of `flask egonet score` and scores the same table
    (from the cache when it can). Without --methods it prints one
    "Label: fact." line each: the convention and threshold grid, the frames,
    the bootstrap (BCa, resamples, seed), the frames without action-object
    pixels and their policy, how people's clicks became maps, and the code
    version. With --methods it writes those facts as a methods paragraph,
    with the frames each kind of row was scored on (as in the table), the
    frame mode, the human study's protocol and the models' splits, then
    the BibTeX entry of the EgoNet paper (Bertasius et al., RSS 2017). For
    a human study, give --frames each: people on their own frames.
    """
    report = _build_report(options)
    text = report.to_methods() if methods else "\n".join(report.describe()) + "\n"
    if out_file is None:
        click.echo(text, nl=False)
        return
    out_file.write_text(text, encoding="utf-8")
    click.echo(f"written: {out_file}", err=True)
