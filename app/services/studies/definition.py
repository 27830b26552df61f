"""A study as a definition file: the builder's settings as one JSON object, to keep under version control.

``study_from_definition(doc)`` creates a study from one (``flask egonet
study-create FILE.json``), ``update_from_definition`` redoes a study nobody
has entered, and ``definition_of(study)`` writes any study's back (the
builder's download). Keys (``KEYS``), all optional but ``name``:

``name``; ``activities`` (names; omitted: all); ``frames_per_activity``
(100); ``seed`` (omitted: a random one, recorded); ``time_limit_minutes``
(60); ``trial_limit_seconds`` (null: none); ``multiple_clicks`` (true);
``sigma_px`` (omitted: the paper's 60 px at 1280 px wide, scaled to the
frames); ``regions`` (the superpixel options, ``{"method": "slic", ...}``);
``instructions``, ``consent``; ``practice_trials`` (a number drawn from the
eligible frames left, or frame ids); ``catch_trials`` (``[{"frame",
"position", "box"}]``); ``comprehension`` (``[{"question", "options",
"answer"}]`` or ``{"questions": [...], "max_attempts": 3}``);
``conditions`` (``[{"name", overrides...}]``); ``activity_order``
(``shuffled`` or ``counterbalanced``); ``open_link`` (``{"cap",
"quotas"}``; omitted: no open link); ``completion`` (``{"code",
"redirect_url", "failed_code"}``); ``display`` (``{"width_px" or
"fraction", "fullscreen", "min_window", "allow_phones"}``).

An unknown key or a bad value is a ``StudyProblem`` whose message starts
with the key (``time_limit_minutes: ...``) and nothing is created.
"""

from typing import Any

from app.extensions import db
from app.models import Activity, User
from app.models.studies import FrameKind, Study
from app.services.studies.building import DEFAULT_CONSENT, DEFAULT_INSTRUCTIONS, OPTION_RULES, create_study
from app.services.studies.common import StudyProblem, check_bool, check_int, check_keys, check_number

KEYS = (
    "name", "activities", "frames_per_activity", "seed", "time_limit_minutes", "trial_limit_seconds", "multiple_clicks",
    "sigma_px", "regions", "instructions", "consent", "practice_trials", "catch_trials", "comprehension", "conditions",
    "activity_order", "open_link", "completion", "display",
)  # fmt: skip
# The builder's field names -> the definition's keys, where they differ.
SERVICE_FIELDS = {
    "time_limit_s": "time_limit_minutes",
    "trial_limit_s": "trial_limit_seconds",
    "superpixel_method": "regions.method",
    "fine_regions": "regions.fine_regions",
    "level": "regions.level",
    "max_region_share": "regions.max_region_share",
    "n_segments": "regions.n_segments",
    "compactness": "regions.compactness",
    "scale": "regions.scale",
    "min_size": "regions.min_size",
    "max_side": "regions.max_side",
}


def _settings(doc: Any) -> dict[str, Any]:
    """The keyword arguments of ``create_study`` for a definition document."""
    check_keys(doc, "", KEYS)
    if "name" not in doc:
        raise StudyProblem("name: a study needs a name", field="name")
    settings: dict[str, Any] = {"name": doc["name"] if isinstance(doc["name"], str) else ""}
    settings["activity_ids"] = _activity_ids(doc.get("activities"))
    for key in ("frames_per_activity", "seed"):
        if doc.get(key) is not None:
            settings[key] = check_int(doc[key], key, 0 if key == "seed" else 1, 2**31 - 1)
    if doc.get("time_limit_minutes") is not None:
        settings["time_limit_s"] = max(1, round(check_number(doc["time_limit_minutes"], "time_limit_minutes", 0.05, 7 * 24 * 60) * 60))
    if doc.get("trial_limit_seconds") is not None:
        settings["trial_limit_s"] = check_int(doc["trial_limit_seconds"], "trial_limit_seconds", 1, 24 * 3600)
    if doc.get("multiple_clicks") is not None:
        settings["multiple_clicks"] = check_bool(doc["multiple_clicks"], "multiple_clicks")
    if doc.get("sigma_px") is not None:
        settings["sigma_px"] = check_number(doc["sigma_px"], "sigma_px", 0.5, 10_000)
    if doc.get("regions") is not None:
        settings["superpixels"] = check_keys(doc["regions"], "regions", ("method", *OPTION_RULES, "max_side"))
    settings["instructions"] = doc.get("instructions", DEFAULT_INSTRUCTIONS)
    settings["consent"] = doc.get("consent", DEFAULT_CONSENT)
    for key in ("practice_trials", "catch_trials", "comprehension", "conditions", "open_link", "completion", "display", "activity_order"):
        if doc.get(key) is not None:
            settings[key] = doc[key]
    return settings


def _activity_ids(names: Any) -> list[int]:
    activities = {a.name: a.id for a in db.session.execute(db.select(Activity)).scalars()}
    if names is None:
        return sorted(activities.values())
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise StudyProblem("activities must be a list of activity names", field="activities")
    unknown = [n for n in names if n not in activities]
    if unknown:
        raise StudyProblem(f"activities: there is no activity called {unknown[0]!r}", field="activities")
    return [activities[n] for n in names]


def _named(exc: StudyProblem) -> StudyProblem:
    """The service's error, its field and message in the definition's terms (the message starts with the key)."""
    key = SERVICE_FIELDS.get(exc.field or "", exc.field or "definition")
    message = exc.message
    for service, named in SERVICE_FIELDS.items():
        if message.startswith(service + " "):
            message = named + message[len(service) :]
    if not message.startswith(key):
        message = f"{key}: {message}"
    return StudyProblem(message, field=key, status=exc.status)


def study_from_definition(doc: Any, *, created_by: User | None = None) -> Study:
    """Create a study from a definition document (see the module doc). Raises StudyProblem naming the key."""
    try:
        return create_study(**_settings(doc), created_by=created_by)
    except StudyProblem as exc:
        db.session.rollback()
        raise _named(exc) from None


def update_from_definition(study: Study, doc: Any, *, version: int) -> Study:
    """Redo ``study`` (still at ``version``, nobody entered) from a definition document."""
    try:
        return create_study(**_settings(doc), study=study, version=version)
    except StudyProblem as exc:
        db.session.rollback()
        raise _named(exc) from None


def definition_of(study: Study) -> dict[str, Any]:
    """The study's settings as a definition document (re-creating from it draws the same frames over the same data)."""
    main = study.frames_of(FrameKind.MAIN)
    doc: dict[str, Any] = {
        "name": study.name,
        "activities": sorted({sf.frame.sequence.activity.name for sf in main}),
        "frames_per_activity": study.frames_per_activity,
        "seed": study.seed,
        "time_limit_minutes": round(study.time_limit_s / 60, 4),
        "trial_limit_seconds": study.trial_limit_s,
        "multiple_clicks": study.multiple_clicks,
    }
    if not study.sigma_scaled:
        doc["sigma_px"] = study.sigma_px
    doc["regions"] = dict(study.superpixels)
    doc["instructions"] = study.instructions
    doc["consent"] = study.consent
    doc["activity_order"] = study.activity_order.value
    practice = study.frames_of(FrameKind.PRACTICE)
    if practice:
        doc["practice_trials"] = [sf.frame_id for sf in practice]
    catch = study.frames_of(FrameKind.CATCH)
    if catch:
        doc["catch_trials"] = [
            {"frame": sf.frame_id, "position": sf.catch_position, **({"box": sf.region["box"]} if sf.region else {})} for sf in catch
        ]
    if study.comprehension:
        doc["comprehension"] = study.comprehension
    if study.conditions:
        doc["conditions"] = [{"name": c.name, **c.overrides} for c in study.conditions]
    if study.open_link_token:
        quotas = {c.name: c.quota for c in study.conditions if c.quota is not None}
        doc["open_link"] = {"cap": study.cap, **({"quotas": quotas} if quotas else {})}
    completion = {"code": study.completion_code, "redirect_url": study.redirect_url, "failed_code": study.failed_code}
    if any(completion.values()):
        doc["completion"] = {k: v for k, v in completion.items() if v is not None}
    if study.display:
        doc["display"] = dict(study.display)
    return doc
