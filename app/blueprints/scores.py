"""The Scores page: Table 2 for this project, with precision-recall curves and downloads.

The choice of runs and studies travels in the query string (checkboxes in a
GET form), so a table can be bookmarked and its downloads repeat it. Without
``chosen`` in the query, the page scores every completed run, every study and
the baselines.
"""

from flask import Blueprint, Response, render_template, request

from app.services import scoring

bp = Blueprint("scores", __name__, url_prefix="/scores")

DOWNLOADS = {
    "csv": ("text/csv", lambda r: r.to_csv()),
    "tex": ("application/x-tex", lambda r: r.to_latex()),
    "json": ("application/json", lambda r: r.to_json()),
}


def _ids(name: str) -> list[int]:
    values = request.args.getlist(name)
    try:
        return [int(v) for v in values]
    except ValueError:
        raise scoring.ScoringProblem(f"{name} must be whole numbers (ids)", fields={name: "must be whole numbers"}) from None


def _choice() -> dict:
    """The runs, studies and baselines the query string asks for (defaults: everything)."""
    if "chosen" not in request.args:
        return {"run_ids": None, "study_ids": None, "baselines": True}
    return {"run_ids": _ids("runs"), "study_ids": _ids("studies"), "baselines": "baselines" in request.args}


def _query(choice: dict, runs: list, studies: list) -> dict:
    """Query values that repeat this choice (for the download links)."""
    query = {
        "chosen": 1,
        "runs": [run.id for run in runs] if choice["run_ids"] is None else choice["run_ids"],
        "studies": [study.id for study, _ in studies] if choice["study_ids"] is None else choice["study_ids"],
    }
    if choice["baselines"]:
        query["baselines"] = 1
    return query


@bp.get("/")
def index():
    choice = _choice()
    report = scoring.build_report(**choice)
    plots = [scoring.pr_plot(report, key) for key in ([scoring.ALL, *report.activities] if report.rows else [])]
    runs, studies = scoring.available_runs(), scoring.available_studies()
    query = _query(choice, runs, studies)
    return render_template(
        "scores/index.html",
        report=report,
        plots=plots,
        best=report.best(),
        runs=runs,
        studies=studies,
        chosen_runs=set(query["runs"]),
        chosen_studies=set(query["studies"]),
        baselines=choice["baselines"],
        query=query,
        definition=scoring.DEFINITION,
    )


@bp.get("/table.<any(csv, tex, json):table_format>")
def download(table_format: str):
    """The table as CSV, LaTeX (booktabs) or JSON (with the curves), for the same choice as the page."""
    report = scoring.build_report(**_choice())
    mimetype, render = DOWNLOADS[table_format]
    headers = {"Content-Disposition": f'attachment; filename="scores.{table_format}"'}
    return Response(render(report), mimetype=mimetype, headers=headers)
