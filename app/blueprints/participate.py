"""The participant side of a human study: consent, instructions, timed trials.

(The admin side is ``app.blueprints.studies``. This blueprint keeps its
registered name ``study`` and its URLs under ``/s``.)

A participant enters with an access code (a public form) or a single-use
link, which signs them in as their participant user. Opening the link shows
a Start button; only pressing it (a POST) uses the link, so a link-preview
bot that fetches it does not burn it. Wrong codes and unknown links are
throttled per address, like log-in (``app.throttle``). Every other page and
call needs that sign-in (``@roles(Role.PARTICIPANT)``) and goes through
``_participant`` / ``_owned_trial``, which load the caller's own enrolment
and trial and refuse anything else, so one participant can never reach
another's session. The only images served here are the frames of the
participant's trial on screen and the next one; ground truth never leaves
the server. Nothing here may be stored by the browser (``no-store``): Back
after the end must not bring back a trial with its clock running.
"""

from flask import Blueprint, redirect, render_template, request, send_file, url_for
from flask_login import current_user, login_user
from app.forms import Form
from werkzeug.wrappers import Response
from wtforms import StringField
from wtforms.validators import DataRequired, Length

from app.errors import Problem
from app.extensions import db
from app.models import Role
from app.models.studies import EventKind, Participant, Trial
from app.security import public, roles
from app.services import media
from app.services import studies
from app.throttle import address, failed, failures_limit, limiter, too_many_attempts
from app.validation import Bool, Float, Int, List, Obj, Str, json_body

bp = Blueprint("study", __name__, url_prefix="/s")

STEP_ENDPOINTS = {
    "consent": "study.consent",
    "instructions": "study.instructions",
    "trials": "study.trials",
    "done": "study.done",
}
DAY_MS = 24 * 3600 * 1000.0
CLIENT_EVENTS = {k.value for k in EventKind if k is not EventKind.RELOAD}

CLICK = Obj({"x": Float(), "y": Float(), "rt_ms": Float(min=0, max=DAY_MS)})
EVENT = Obj(
    {
        "kind": Str(choices=CLIENT_EVENTS),
        "t_ms": Float(min=-DAY_MS, max=DAY_MS),
        "state": Str(choices={"visible", "hidden", "prerender"}, default=None, nullable=True),
        "width": Int(min=0, max=100_000, default=None, nullable=True),
        "height": Int(min=0, max=100_000, default=None, nullable=True),
        "x": Float(default=None, nullable=True),
        "y": Float(default=None, nullable=True),
    }
)
ANSWER = {
    "clicks": List(CLICK, max_len=studies.MAX_CLICKS),
    "none": Bool(default=False),
    "timed_out": Bool(default=False),
    "rt_ms": Float(min=0, max=DAY_MS, default=None, nullable=True),
    "events": List(EVENT, max_len=studies.MAX_EVENTS, default=[]),
    "window": Obj({"width": Int(min=0, max=100_000), "height": Int(min=0, max=100_000)}, default=None, nullable=True),
    "display": Obj({"width": Float(min=0, max=100_000), "height": Float(min=0, max=100_000)}, default=None, nullable=True),
    "pixel_ratio": Float(min=0, max=100, default=None, nullable=True),
}


# Wrong codes and unknown links count together, per address; past the limit
# the entry form and links answer 429 until the window ends. A success does
# not forgive earlier failures: with one code of their own, a guesser could
# otherwise reset the count at will.
guesses = limiter.shared_limit(
    failures_limit, scope="study-entry", key_func=address, deduct_when=failed, error_message=too_many_attempts
)


class CodeForm(Form):
    code = StringField("Access code", validators=[DataRequired(), Length(max=32)])


@bp.after_request
def never_stored(response: Response) -> Response:
    """after_request: no participant page, answer or frame is kept by the browser (see above)."""
    response.headers["Cache-Control"] = "no-store"
    return response


def _participant() -> Participant:
    """The signed-in user's own enrolment, with time-up applied; 403 for anyone else."""
    participant = studies.participant_of(current_user) if current_user.is_authenticated else None
    if participant is None:
        raise Problem("you are not enrolled in a study; use the link or code you were given", status=403)
    return studies.refresh(participant)


def _owned_trial(trial_id: int) -> tuple[Participant, Trial]:
    """The signed-in participant and one of their own trials; 404 for any other trial."""
    participant = _participant()
    trial = db.session.get(Trial, trial_id)
    if trial is None or trial.participant_id != participant.id:
        raise Problem("no such trial", status=404)
    return participant, trial


def _go_to_step(participant: Participant) -> Response:
    return redirect(url_for(STEP_ENDPOINTS[studies.step(participant)]))


def _sign_in(participant: Participant) -> Response:
    if not login_user(participant.user):
        raise Problem("this participant has been deactivated", status=403)
    return _go_to_step(participant)


@bp.route("/", methods=["GET", "POST"])
@public
@guesses
def entry():
    if request.method == "GET" and current_user.is_authenticated and current_user.role is Role.PARTICIPANT:
        participant = studies.participant_of(current_user)
        if participant is not None:
            return _go_to_step(studies.refresh(participant))
    form = CodeForm()
    status = 200
    if form.validate_on_submit():
        participant = studies.participant_by_code(form.code.data)
        if participant is not None:
            return _sign_in(participant)
        form.code.errors.append("This code is not known. Check it and try again.")
        status = 401
    elif form.errors:
        status = 400
    return render_template("study/entry.html", form=form), status


@bp.route("/l/<token>", methods=["GET", "POST"])
@public
@guesses
def link(token: str):
    """A single-use link: GET shows the Start button, the POST it sends signs in and uses the link."""
    if request.method == "GET":
        participant = studies.link_participant(token)
        return render_template("study/link.html", study=participant.study, trials=len(participant.trials))
    return _sign_in(studies.use_link(token))


@bp.route("/consent", methods=["GET", "POST"])
@roles(Role.PARTICIPANT)
def consent():
    participant = _participant()
    if request.method == "POST":
        decision = request.form.get("decision")
        if decision not in ("agree", "decline"):
            raise Problem("answer agree or decline", fields={"decision": "must be agree or decline"})
        studies.answer_consent(participant, agree=decision == "agree")
        return _go_to_step(participant)
    if studies.step(participant) != "consent":
        return _go_to_step(participant)
    return render_template("study/consent.html", study=participant.study)


@bp.get("/instructions")
@roles(Role.PARTICIPANT)
def instructions():
    participant = _participant()
    if studies.step(participant) != "instructions":
        return _go_to_step(participant)
    return render_template(
        "study/instructions.html",
        participant=participant,
        study=participant.study,
        trials=len(participant.trials),
        code=studies.format_code(participant.code),
    )


@bp.post("/start")
@roles(Role.PARTICIPANT)
def start():
    participant = _participant()
    studies.start_session(participant)
    return _go_to_step(participant)


@bp.get("/trials")
@roles(Role.PARTICIPANT)
def trials():
    participant = _participant()
    if studies.step(participant) != "trials":
        return _go_to_step(participant)
    return render_template("study/trials.html", study=participant.study)


@bp.get("/done")
@roles(Role.PARTICIPANT)
def done():
    participant = _participant()
    if studies.step(participant) != "done":
        return _go_to_step(participant)
    return render_template("study/done.html", participant=participant, progress=studies.progress(participant))


def _state_json(state: studies.SessionState) -> dict:
    body = {
        "step": state.step,
        "end_reason": state.end_reason.value if state.end_reason else None,
        "done": state.done,
        "total": state.total,
        "time_left_s": state.time_left_s,
        "trial_time_left_s": state.trial_time_left_s,
        "redirect": None if state.step == "trials" else url_for(STEP_ENDPOINTS[state.step]),
        "trial": None,
        "next": None,
    }
    for key, trial in (("trial", state.trial), ("next", state.next_trial)):
        if trial is not None:
            frame = trial.frame
            body[key] = {
                "id": trial.id,
                "position": trial.position,
                "width": frame.width,
                "height": frame.height,
                "image_url": url_for("study.image", trial_id=trial.id),
                "submit_url": url_for("study.submit", trial_id=trial.id),
            }
    return body


@bp.get("/api/current")
@roles(Role.PARTICIPANT)
def current():
    """The trial on screen (a reload resumes at the first unanswered trial)."""
    return _state_json(studies.session_state(_participant(), reload=True))


@bp.post("/api/trials/<int:trial_id>")
@roles(Role.PARTICIPANT)
def submit(trial_id: int):
    """Answer a trial; the reply is the next state, like ``current``."""
    participant, trial = _owned_trial(trial_id)
    data = json_body(ANSWER)
    answer = studies.Answer(
        clicks=[(c["x"], c["y"], c["rt_ms"]) for c in data["clicks"]],
        none=data["none"],
        timed_out=data["timed_out"],
        rt_ms=data["rt_ms"],
        events=[
            studies.ClientEvent(
                kind=EventKind(e["kind"]),
                client_ms=e["t_ms"],
                detail={k: v for k, v in e.items() if k not in ("kind", "t_ms") and v is not None},
            )
            for e in data["events"]
        ],
        window_width=(data["window"] or {}).get("width"),
        window_height=(data["window"] or {}).get("height"),
        display_width=(data["display"] or {}).get("width"),
        display_height=(data["display"] or {}).get("height"),
        pixel_ratio=data["pixel_ratio"],
    )
    return _state_json(studies.submit(participant, trial, answer))


@bp.get("/trials/<int:trial_id>/image")
@roles(Role.PARTICIPANT)
def image(trial_id: int):
    """The RGB frame of the participant's trial on screen or the next one (never depth, DHG or ground truth)."""
    participant, trial = _owned_trial(trial_id)
    path = media.absolute_path(studies.trial_frame(participant, trial).rgb_path)
    mimetype = "image/jpeg" if path.suffix.lower() in (".jpg", ".jpeg") else "image/png"
    return send_file(path, mimetype=mimetype)
