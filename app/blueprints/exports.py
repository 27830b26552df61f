"""Exports from the Label page: the form's answer (a zip, or a job for the worker), the job's page and download.

All staff may export (the same data they can browse). A form whose filters
select nothing, or that is wrong, goes back to the Label page with the
reason and the choices kept; it never downloads an empty zip.
"""

from flask import Blueprint, flash, redirect, render_template, request, send_file, url_for
from flask_login import current_user

from app.services import exchange

bp = Blueprint("exports", __name__)

# The export form's fields, as the Label page's query keeps them.
FORM_FIELDS = ("format", "images", "status", "activity", "annotator")


def options_from(values) -> "exchange.ExportOptions":
    """The export form's choices (``request.form`` or the Label page's query) as checked options."""
    return exchange.ExportOptions.of(
        fmt=values.get("format", "both"),
        images=values.get("images") == "1",
        activities=values.getlist("activity"),
        statuses=values.getlist("status"),
        annotators=values.getlist("annotator"),
    )


def form_values(values) -> dict:
    """What the Label page's export form shows: the last choices (from its query), else the defaults."""
    if not any(name in values for name in FORM_FIELDS):
        return {"format": "both", "images": False, "status": [s.value for s in exchange.DEFAULT_STATUSES],
                "activity": [], "annotator": []}
    return {"format": values.get("format", "both"), "images": values.get("images") == "1",
            "status": values.getlist("status"), "activity": values.getlist("activity"),
            "annotator": values.getlist("annotator")}


@bp.post("/label/exports")
def create():
    """The export form: a zip at once when it is small, else a job for the worker (its page)."""
    try:
        options = options_from(request.form)
        plan = exchange.plan_export(options)
        if exchange.fits_a_request(options, plan):
            archive, report = exchange.export_zip(options)
            response = send_file(archive, mimetype="application/zip", as_attachment=True,
                                 download_name="egonet-export.zip")
            response.headers["X-Exported-Frames"] = str(report.frames)
            return response
        job = exchange.queue_export(options, current_user._get_current_object(), plan)
    except exchange.ExchangeProblem as exc:
        message = exc.message.removeprefix("--")
        flash(message[:1].upper() + message[1:] + ".", "export")  # shown in the Label page's export card
        kept = {name: request.form.getlist(name) for name in FORM_FIELDS if name in request.form}
        return redirect(url_for("label.index", **kept, _anchor="export"))
    flash(f"Export {job.id} ({plan.frames} frame{'' if plan.frames == 1 else 's'}) is queued: "
          "it is built in the background, and this page follows it.", "info")
    return redirect(url_for("exports.detail", export_id=job.id))


def export_json(job) -> dict:
    return {
        "id": job.id,
        "status": job.status.value,
        "done": job.done,
        "total": job.total,
        "annotations": job.annotations,
        "instances": job.instances,
        "size_bytes": job.size_bytes,
        "message": job.message,
        "download_url": url_for("exports.download", export_id=job.id) if job.status.value == "done" else None,
    }


@bp.get("/label/exports/<int:export_id>")
def detail(export_id: int):
    job = exchange.get_export(export_id)
    return render_template("label/export.html", job=job, options=exchange.ExportOptions.from_dict(job.options),
                           state=export_json(job))


@bp.get("/api/label/exports/<int:export_id>")
def status(export_id: int):
    """The export's progress (polled by its page)."""
    return export_json(exchange.get_export(export_id))


@bp.get("/label/exports/<int:export_id>/download")
def download(export_id: int):
    job = exchange.get_export(export_id)
    return send_file(exchange.export_file(job), mimetype="application/zip", as_attachment=True,
                     download_name=f"egonet-export-{job.id}.zip", conditional=True)
