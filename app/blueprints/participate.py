"""The participant side of a human study: entering, consent, instructions and questions, practice, timed trials, the end.

(The admin side is ``app.blueprints.studies``. This blueprint keeps its
registered name ``study`` and its URLs under ``/s``.)

A participant enters with an access code (a public form), a single-use
link, or the study's open link (``/s/o/<token>``, with a recruiting
platform's parameters such as ``PROLIFIC_PID``), which signs them in as
their participant user. Opening a link shows a Start button; only pressing
it (a POST) uses a single-use link or admits through the open link, so a
link-preview bot that fetches it does neither. Wrong codes and unknown
links are throttled per address (whatever study the URL names), and so are
newcomers' admissions through each study's open link, apart from codes
(``app.throttle``): past a generous budget the address waits a little
longer before each try, it is never locked out. The open link's pages,
refusals included, may be framed by MTurk only (its HIT shows them);
every other page is never framed. Every other page and call needs that
sign-in (``@roles(Role.PARTICIPANT)``) and goes through ``_participant`` /
``_owned_trial``, which load the caller's own enrolment and trial and refuse
anything else, so one participant can never reach another's session. The
only images served here are the frames of the participant's trial on screen
and the next one; ground truth never leaves the server. Nothing here may be
stored by the browser (``no-store``): Back after the end must not bring back
a trial with its clock running.
"""

import re

from flask import Blueprint, redirect, render_template, request, send_file, url_for
from flask_login import current_user, login_user
from werkzeug.wrappers import Response

from app.errors import Problem
from app.extensions import db
from app.forms import CodeForm
from app.models import Role
from app.models.studies import EventKind, FrameKind, Participant, Study, Trial
from app.security import CONTENT_SECURITY_POLICY, public, roles
from app.services import media, studies
from app import throttle
from app.throttle import entry_attempts
from app.validation import MIB, Bool, Float, Int, List, Obj, Str, json_body, takes_json

bp = Blueprint("study", __name__, url_prefix="/s")

STEP_ENDPOINTS = {
    "consent": "study.consent",
    "instructions": "study.instructions",
    "practice": "study.practice",
    "ready": "study.ready",
    "trials": "study.trials",
    "done": "study.done",
}
DAY_MS = 24 * 3600 * 1000.0
CLIENT_EVENTS = {k.value for k in EventKind if k is not EventKind.RELOAD}
# Phones, from the browser's own words (the page checks the pointer and the window too).
PHONE = re.compile(r"iPhone|iPod|Android.*Mobile|Windows Phone|IEMobile|BlackBerry|Opera Mini|Mobile.*Firefox", re.I)
SIZE = Obj({"width": Int(min=0, max=100_000), "height": Int(min=0, max=100_000)}, default=None, nullable=True)

CLICK = Obj({"x": Float(), "y": Float(), "rt_ms": Float(min=0, max=DAY_MS)})
EVENT = Obj(
    {
        "kind": Str(choices=CLIENT_EVENTS),
        "t_ms": Float(min=-DAY_MS, max=DAY_MS),
        "state": Str(choices={"visible", "hidden", "prerender", "entered", "exited"}, default=None, nullable=True),
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
ENVIRONMENT = {
    "screen": SIZE,
    "window": SIZE,
    "pixel_ratio": Float(min=0, max=100, default=None, nullable=True),
    "time_zone": Str(max_len=64, default=None, nullable=True),
    "touch": Bool(default=None, nullable=True),
}
TIME_ZONE = re.compile(r"[A-Za-z0-9_+\-/]{1,64}")


@bp.after_request
def never_stored(response: Response) -> Response:
    """after_request: no participant page, answer or frame is kept by the browser; the open link's pages,
    whatever they answer, may be framed by MTurk (see above)."""
    response.headers["Cache-Control"] = "no-store"
    if request.endpoint == "study.open_link":
        _set_policy(response, "frame-ancestors", studies.mturk_submit_hosts())
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


def _notice(title: str, message: str, status: int) -> tuple[str, int]:
    return render_template("study/notice.html", title=title, message=message), status


def _refused(exc: studies.StudyProblem):
    """A polite page for a study that takes nobody now (full, paused, closed)."""
    titles = {"full": "This study is full", "paused": "This study is paused", "closed": "This study is closed",
              "elsewhere": "Please continue in your first browser", "withdrawn": "You have withdrawn from this study"}  # fmt: skip
    return _notice(titles.get(exc.extra.get("reason"), "Not now"), exc.message, exc.status)


def _device_refused(study: Study):
    """A phone, when the study needs a computer: said before anything else (None when the device may take part)."""
    if study.display.get("allow_phones", True) or not PHONE.search(request.user_agent.string or ""):
        return None
    return _notice("This study needs a computer", "It cannot be done on a phone: please open the same link on a desktop or laptop.", 403)


def _sign_in(participant: Participant) -> Response:
    if not login_user(participant.user):
        raise Problem("this participant has been deactivated", status=403)
    return _go_to_step(participant)


def _enter(participant: Participant):
    """Sign in a participant who came by code or link, unless their study refuses newcomers or their device."""
    refused = _device_refused(participant.study)
    if refused is not None:
        return refused
    try:
        studies.check_may_enter(participant)
    except studies.StudyProblem as exc:
        return _refused(exc)
    return _sign_in(participant)


@bp.route("/", methods=["GET", "POST"])
@public
@entry_attempts
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
            return _enter(participant)
        form.code.errors.append("This code is not known. Check it and try again.")
        status = 401
    elif form.errors:
        status = 400
    return render_template("study/entry.html", form=form), status


@bp.route("/l/<token:token>", methods=["GET", "POST"])
@public
@entry_attempts
def link(token: str):
    """A single-use link: GET shows the Start button, the POST it sends signs in and uses the link."""
    participant = studies.link_participant(token)
    if request.method == "GET":
        refused = _device_refused(participant.study)
        if refused is not None:
            return refused
        return render_template("study/link.html", study=participant.study, trials=studies.progress(participant).total)
    try:
        studies.check_may_enter(participant)
    except studies.StudyProblem as exc:
        return _refused(exc)
    return _enter(studies.use_link(token))


@bp.route("/o/<token:open_token>", methods=["GET", "POST"])
@public
def open_link(open_token: str):
    """The study's open link: GET says what the study is (or that it is full, paused or closed); its Start
    (a POST carrying the platform's parameters) admits, or resumes the participant with the same external id
    from their first browser or with their platform's same visit id (``studies.may_resume``)."""
    study = studies.open_link_study(open_token)
    source = request.args if request.method == "GET" else request.form
    arrival = studies.parse_arrival(source)
    refused = _device_refused(study)
    if refused is not None:
        return refused
    known = studies.by_external_id(study, arrival.external_id)
    same_browser = known is not None and current_user.is_authenticated and current_user.id == known.user_id
    if request.method == "GET":
        # Whether an id takes part shows only to whom may resume it: anyone else gets a newcomer's answer
        # (and learns on the POST, as a newcomer would, whether that id may go on).
        if known is not None and not studies.may_resume(known, arrival, same_browser=same_browser):
            known = None
        reason = studies.availability(study) if known is None else studies.returning(known, arrival, same_browser=same_browser)
        if reason is not None:
            return _refused(studies.refusal(reason))
        return render_template(
            "study/open.html", study=study, arrival=arrival, known=known, params=_platform_params(source),
            trials=_timed_trials(study), minutes=study.time_limit_s / 60, example=studies.example_frame(study),
            framed=request.headers.get("Sec-Fetch-Dest") == "iframe",
        )  # fmt: skip
    newcomer = known is None and not arrival.preview
    wait = throttle.open_admission(study.id) if newcomer else 0
    if wait:
        return throttle.too_many(wait)
    try:
        participant = studies.admit(study, arrival, user_agent=request.user_agent.string, same_browser=same_browser)
    except studies.StudyProblem as exc:
        if newcomer:
            throttle.not_admitted(study.id)
        if exc.status == 400:
            raise
        return _refused(exc)
    return _sign_in(participant)


@bp.get("/o/<token:open_token>/example")
@public
def open_example(open_token: str):
    """The frame an MTurk preview shows with the instructions, before anyone is admitted (no ground truth)."""
    example = studies.example_frame(studies.open_link_study(open_token))
    if example is None:
        raise Problem("this study has no frames", status=404)
    path = media.local_path(example.frame.rgb_path)
    return send_file(path, mimetype="image/jpeg" if path.suffix.lower() in (".jpg", ".jpeg") else "image/png")


def _set_policy(response: Response, directive: str, sources) -> Response:
    """``response`` under the app's Content-Security-Policy with ``directive``'s sources replaced (to let MTurk in)."""
    policy = [p for p in CONTENT_SECURITY_POLICY.split("; ") if not p.startswith(directive + " ")]
    response.headers["Content-Security-Policy"] = "; ".join([*policy, " ".join([directive, *sources])])
    return response


def _platform_params(source) -> dict[str, str]:
    """The platform's parameters, to carry from the link's GET to its Start button (already checked)."""
    names = [name for _, id_param, others in studies.PLATFORMS for name in (id_param, *others)]
    return {name: source[name] for name in names if source.get(name)}


def _timed_trials(study: Study) -> int:
    return len(study.frames) - len(study.frames_of(FrameKind.PRACTICE))


def _steps(participant: Participant) -> list[str]:
    has_practice = bool(participant.study.frames_of(FrameKind.PRACTICE))
    return ["Consent", "Instructions", *(["Practice"] if has_practice else []), "Photos", "Done"]


def _page(template: str, participant: Participant, current: str, **context):
    return render_template(template, participant=participant, study=participant.study, steps=_steps(participant), current=current,
                           **context)  # fmt: skip


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
    return _page("study/consent.html", participant, "Consent")


def _instructions_page(participant: Participant, *, wrong: bool = False, left: int | None = None, status: int = 200):
    settings = studies.settings_of(participant)
    return _page(
        "study/instructions.html", participant, "Instructions",
        settings=settings, trials=studies.progress(participant).total, practice=len(participant.study.frames_of(FrameKind.PRACTICE)),
        questions=participant.study.comprehension.get("questions") or [], wrong=wrong, left=left,
        code=studies.format_code(participant.code),
    ), status  # fmt: skip


@bp.get("/instructions")
@roles(Role.PARTICIPANT)
def instructions():
    participant = _participant()
    if studies.step(participant) != "instructions":
        return _go_to_step(participant)
    return _instructions_page(participant)


@bp.post("/comprehension")
@roles(Role.PARTICIPANT)
def comprehension():
    """One try at the questions on the instructions: every answer right goes on; wrong ones show the page again."""
    participant = _participant()
    questions = participant.study.comprehension.get("questions") or []
    if studies.step(participant) != "instructions" or not questions:
        return _go_to_step(participant)
    answers = _answers(len(questions))
    left = studies.answer_comprehension(participant, answers)
    if studies.step(participant) != "instructions":
        return _go_to_step(participant)
    return _instructions_page(participant, wrong=True, left=left, status=400)


def _answers(count: int) -> dict[int, int]:
    """``q0``..``q{count-1}`` -> option index; anything else in the form is refused (a bounded body)."""
    expected = {f"q{i}" for i in range(count)} | {"csrf_token"}
    unknown = sorted(k for k in request.form if k not in expected)
    if unknown:
        raise Problem(f"{unknown[0]}: there is no such question", fields={unknown[0]: "unknown field"})
    answers = {}
    for i in range(count):
        value = request.form.get(f"q{i}", "")
        if value.isascii() and value.isdigit() and len(value) <= 2:
            answers[i] = int(value)
    return answers


@bp.post("/start")
@roles(Role.PARTICIPANT)
def start():
    participant = _participant()
    studies.start_session(participant)
    return _go_to_step(participant)


@bp.get("/practice")
@roles(Role.PARTICIPANT)
def practice():
    participant = _participant()
    if studies.step(participant) != "practice":
        return _go_to_step(participant)
    return _trial_page(participant, "practice")


@bp.get("/ready")
@roles(Role.PARTICIPANT)
def ready():
    participant = _participant()
    if studies.step(participant) != "ready":
        return _go_to_step(participant)
    settings = studies.settings_of(participant)
    return _page("study/ready.html", participant, "Photos", settings=settings, trials=studies.progress(participant).total)


@bp.get("/trials")
@roles(Role.PARTICIPANT)
def trials():
    participant = _participant()
    if studies.step(participant) != "trials":
        return _go_to_step(participant)
    return _trial_page(participant, "trials")


def _trial_page(participant: Participant, phase: str):
    return render_template("study/trials.html", study=participant.study, phase=phase, display=participant.study.display)


@bp.get("/done")
@roles(Role.PARTICIPANT)
def done():
    participant = _participant()
    if studies.step(participant) != "done":
        return _go_to_step(participant)
    code, redirect_url = studies.completion(participant)
    mturk_url = studies.mturk_submit_url(participant) if code else None
    page = _page("study/done.html", participant, "Done", progress=studies.progress(participant), code=code,
                 redirect_url=None if mturk_url else redirect_url, mturk_url=mturk_url)  # fmt: skip
    return _set_policy(Response(page, mimetype="text/html"), "form-action", ["'self'", *([mturk_url] if mturk_url else [])])


def _state_json(state: studies.SessionState) -> dict:
    body = {
        "step": state.step,
        "end_reason": state.end_reason.value if state.end_reason else None,
        "done": state.done,
        "total": state.total,
        "time_left_s": state.time_left_s,
        "trial_time_left_s": state.trial_time_left_s,
        "shown_ms": state.shown_ms,
        "feedback": state.feedback,
        "redirect": None if state.step in ("trials", "practice") else url_for(STEP_ENDPOINTS[state.step]),
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
@takes_json(MIB)
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


@bp.post("/api/environment")
@roles(Role.PARTICIPANT)
@takes_json()
def environment():
    """What the page reports of the screen, window, pixel ratio and time zone (stored with the session)."""
    participant = _participant()
    data = json_body(ENVIRONMENT)
    if data["time_zone"] is not None and not TIME_ZONE.fullmatch(data["time_zone"]):
        raise Problem("invalid field time_zone: an IANA name such as Europe/Paris", fields={"time_zone": "not a time zone name"})
    studies.record_environment(participant, data, user_agent=request.user_agent.string)
    return {"recorded": True}


@bp.get("/trials/<int:trial_id>/image")
@roles(Role.PARTICIPANT)
def image(trial_id: int):
    """The RGB frame of the participant's trial on screen or the next one (never depth, DHG or ground truth)."""
    participant, trial = _owned_trial(trial_id)
    path = media.local_path(studies.trial_frame(participant, trial).rgb_path)
    mimetype = "image/jpeg" if path.suffix.lower() in (".jpg", ".jpeg") else "image/png"
    return send_file(path, mimetype=mimetype)
