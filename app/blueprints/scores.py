"""The Scores page: Table 2 for this project, with intervals, comparisons, precision-recall curves and downloads.

Everything travels in the query string (a GET form), so a table can be
bookmarked and its downloads repeat it:

* what to score: ``chosen``, ``runs``, ``studies``, ``baselines`` (without
  ``chosen``: every completed run of the table, every study and the baselines);
* ``trained_on`` (repeated, an activity each): the table's training set, for
  models scored where they were never trained (the paper's Tables 3 and 4):
  its runs are those trained on every frame of exactly these activities, its
  baselines are fitted on them, its columns are the other activities;
  without it, leave-one-activity-out (Table 2);
* how: ``metric`` (``pooled``, ``ois-mean``, ``mean-curve``, ``ods-ois``;
  the old ``per-image`` still works, with a note), ``frames`` (``shared``,
  ``each``), ``empty`` (frames without action-object pixels: ``leave-out``,
  ``zero``, ``one-if-empty``), ``answered_only``, ``exclude_failed_checks``,
  ``by_condition``, ``columns`` (``activities``, or ``sequences``: each
  activity's recordings); the page always uses 1,000 resamples (more, from
  ``flask egonet score --resamples``);
* ``compare_a`` / ``compare_b``: two row keys to compare (the comparison
  downloads from ``/scores/comparison.<csv|tex|json>``);
* ``plotted`` and ``plot``: the rows the precision-recall plots draw.

Participants' rows (``studies``) are for admins only, the people who run
studies: annotators and reviewers see the runs and the baselines, and a
choice of studies is refused them (403). A participant's scores are
research data about a person, which a study's ethics approval lets only its
research team see; anonymising the rows would not do, since in a small
study of colleagues a row's pattern (and the count of rows) can tell who
it is.
"""

from flask import Blueprint, Response, render_template, request

from app.errors import Problem
from app.models import Role
from app.security import current_role
from app.services import scoring
from app.validation import query_ints
from egonet.metrics import DEFAULT_EMPTY, MIN_FRAMES

bp = Blueprint("scores", __name__, url_prefix="/scores")

DOWNLOADS = {
    "csv": ("text/csv", lambda r: r.to_csv()),
    "tex": ("application/x-tex", lambda r: r.to_latex()),
    "json": ("application/json", lambda r: r.to_json()),
}
"""How the table and a comparison (both have the three renderers) download."""
FIGURES = {"svg": "image/svg+xml", "pdf": "application/pdf"}


def _sees_people() -> bool:
    """Whether the user may see study participants' scores (admins only: see docs/scoring.md)."""
    return current_role() is Role.ADMIN


def _choice() -> dict:
    """The runs, studies and baselines the query string asks for (defaults: everything the user may see)."""
    trained_on = request.args.getlist("trained_on") or None
    if "chosen" not in request.args:
        return {"run_ids": None, "study_ids": None if _sees_people() else [], "baselines": True, "trained_on": trained_on}
    study_ids = query_ints("studies")
    if study_ids and not _sees_people():
        raise Problem("only admins see the scores of studies' participants", status=403)
    return {"run_ids": query_ints("runs"), "study_ids": study_ids, "baselines": "baselines" in request.args,
            "trained_on": trained_on}


def _studies() -> list:
    """The studies the form offers: all of them to admins, none to others."""
    return scoring.available_studies() if _sees_people() else []


def _view() -> dict:
    """How to score: the convention, the frames, and which of the people's trials and participants count, and how split."""
    return {
        "metric": request.args.get("metric", "pooled"),
        "frames": request.args.get("frames", "shared"),
        "empty": request.args.get("empty", DEFAULT_EMPTY),
        "answered_only": request.args.get("answered_only") == "1",
        "exclude_failed_checks": request.args.get("exclude_failed_checks") == "1",
        "by_condition": request.args.get("by_condition") == "1",
        "columns": request.args.get("columns", "activities"),
    }


def _compare() -> tuple[str, str] | None:
    a, b = request.args.get("compare_a", ""), request.args.get("compare_b", "")
    if not a and not b:
        return None
    if not a or not b:
        raise scoring.ScoringProblem("compare: choose two rows", fields={"compare_a" if not a else "compare_b": "choose a row"})
    for name, key in (("compare_a", a), ("compare_b", b)):
        if len(key) > 200:
            raise scoring.ScoringProblem(f"{name}: not a row key (at most 200 characters)", fields={name: "not a row key"})
    return a, b


def _plot_rows() -> set[str] | None:
    return set(request.args.getlist("plot")) if "plotted" in request.args else None


def _query(choice: dict, view: dict, runs: list, studies: list) -> dict:
    """Query values that repeat this choice and view (for the forms' hidden fields and the download links)."""
    query = {
        "chosen": 1,
        "trained_on": choice["trained_on"] or [],
        "runs": [run.id for run in runs] if choice["run_ids"] is None else choice["run_ids"],
        "studies": [study.id for study, _ in studies] if choice["study_ids"] is None else choice["study_ids"],
        "metric": view["metric"],
        "frames": view["frames"],
        "empty": view["empty"],
    }
    if view["columns"] != "activities":
        query["columns"] = view["columns"]
    if choice["baselines"]:
        query["baselines"] = 1
    for flag in ("answered_only", "exclude_failed_checks", "by_condition"):
        if view[flag]:
            query[flag] = 1
    return query


@bp.get("/")
def index():
    choice, view = _choice(), _view()
    report = scoring.build_report(**choice, **view, compare_keys=_compare(), fit_in_worker=True)
    shown = _plot_rows()
    keys = [scoring.ALL, *report.activities] if report.rows else []
    plots = [scoring.pr_plot(report, key, rows=shown) for key in keys]
    runs, studies = scoring.table_runs(report.provenance.trained_on), _studies()
    query = _query(choice, view, runs, studies) | {"trained_on": list(report.provenance.trained_on)}
    return render_template(
        "scores/index.html",
        report=report,
        plots=plots,
        plot_rows=scoring.default_plot_rows(report) if shown is None else shown,
        best=report.best(),
        runs=runs,
        training_sets=scoring.training_sets(),
        trained_on=list(report.provenance.trained_on),
        studies=studies,
        sees_people=_sees_people(),
        chosen_runs=set(query["runs"]),
        chosen_studies=set(query["studies"]),
        baselines=choice["baselines"],
        baseline_names=[name for name, _ in scoring.baseline_rows()],
        learned_names=[name for name, learned in scoring.baseline_rows() if learned],
        view=view,
        query=query,
        metrics=scoring.METRIC_TITLES,
        metric_short=scoring.METRIC_SHORT,
        frames=scoring.FRAMES,
        empty_titles=scoring.EMPTY_TITLES,
        compare=request.args,
        min_frames=MIN_FRAMES,
    )


@bp.get("/table.<any(csv, tex, json):table_format>")
def download(table_format: str):
    """The table as CSV, LaTeX (booktabs) or JSON (with the curves), for the same choice as the page."""
    report = scoring.build_report(**_choice(), **_view(), fit_in_worker=True, compare_keys=_compare())
    mimetype, render = DOWNLOADS[table_format]
    headers = {"Content-Disposition": f'attachment; filename="scores.{table_format}"'}
    return Response(render(report), mimetype=mimetype, headers=headers)


@bp.get("/comparison.<any(csv, tex, json):table_format>")
def comparison(table_format: str):
    """The comparison of ``compare_a`` and ``compare_b`` as CSV, LaTeX or JSON, for the same choice as the page."""
    keys = _compare()
    if keys is None:
        raise scoring.ScoringProblem("compare: choose two rows", fields={"compare_a": "choose a row", "compare_b": "choose a row"})
    report = scoring.build_report(**_choice(), **_view(), fit_in_worker=True, compare_keys=keys)
    mimetype, render = DOWNLOADS[table_format]
    headers = {"Content-Disposition": f'attachment; filename="comparison.{table_format}"'}
    return Response(render(report.comparison), mimetype=mimetype, headers=headers)


@bp.get("/figure.<any(svg, pdf):figure_format>")
def figure(figure_format: str):
    """One precision-recall plot (``activity``, default all activities) as an SVG or PDF file for a paper."""
    report = scoring.build_report(**_choice(), **_view(), fit_in_worker=True)
    key = request.args.get("activity", scoring.ALL)
    if key != scoring.ALL and key not in report.activities:
        raise scoring.ScoringProblem(f"activity: no row has frames of {key!r}", fields={"activity": "not an activity of the table"})
    body = scoring.pr_figure(report, key, rows=_plot_rows(), file_format=figure_format)
    name = "pr-all" if key == scoring.ALL else "pr-" + "".join(ch if ch.isalnum() else "-" for ch in key)
    headers = {"Content-Disposition": f'attachment; filename="{name}.{figure_format}"'}
    return Response(body, mimetype=FIGURES[figure_format], headers=headers)


def _frame_table():
    view = _view()
    return scoring.frame_table(
        **_choice(),
        activity=request.args.get("activity") or None,
        frames=view["frames"],
        empty=view["empty"],
        answered_only=view["answered_only"],
        sort=request.args.get("sort") or None,
        fit_in_worker=True,
        columns=view["columns"],
    )


@bp.get("/frames")
def frames():
    """Per-frame scores: each frame of one activity with every row's own best F and AP on it (what ois-mean averages)."""
    table = _frame_table()
    choice, view = _choice(), _view()
    query = _query(choice, view, scoring.table_runs(choice["trained_on"] or ()), _studies())
    return render_template("scores/frames.html", table=table, query=query, view=view)


@bp.get("/frames.csv")
def frames_csv():
    table = _frame_table()
    name = "per-frame-" + "".join(ch if ch.isalnum() else "-" for ch in table.activity or "none")
    return Response(table.to_csv(), mimetype="text/csv", headers={"Content-Disposition": f'attachment; filename="{name}.csv"'})
