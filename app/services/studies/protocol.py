"""A study's protocol beyond its frames: display, completion, open link, comprehension, conditions.

Each ``check_*`` takes what a definition file (or the builder's form) holds
and returns it normalised, or raises ``StudyProblem`` naming the key path
(``display.width_px``, ``conditions[1].name``). ``effective`` resolves what
a participant's condition overrides. Every size and count a participant's
page or a definition can set is bounded here.
"""

from dataclasses import dataclass
from typing import Any
from urllib.parse import quote, urlsplit

from app.models.studies import Participant, Study, StudyCondition
from app.services.studies.common import (
    StudyProblem,
    check_bool,
    check_int,
    check_keys,
    check_number,
    check_text,
    check_token,
)

MAX_QUESTIONS = 20
MAX_OPTIONS = 10
MAX_CONDITIONS = 20
MAX_TEXT = 20_000
DISPLAY_KEYS = ("width_px", "fraction", "fullscreen", "min_window", "allow_phones")
COMPLETION_KEYS = ("code", "redirect_url", "failed_code")
OPEN_LINK_KEYS = ("cap", "quotas")
CONDITION_KEYS = ("name", "time_limit_minutes", "trial_limit_seconds", "instructions", "activities", "frames_per_activity")
QUESTION_KEYS = ("question", "options", "answer")
DEFAULT_ATTEMPTS = 3


def check_display(value: Any) -> dict[str, Any]:
    """How the frame is shown: ``width_px`` (CSS pixels) or ``fraction`` (of the window), ``fullscreen``,
    ``min_window`` (``{"width", "height"}`` or ``[w, h]`` in CSS pixels), ``allow_phones`` (default true).

    Returns only the keys that differ from the defaults (the frame fitted to the window, no minimum).
    """
    if value is None:
        return {}
    check_keys(value, "display", DISPLAY_KEYS)
    out: dict[str, Any] = {}
    if value.get("width_px") is not None and value.get("fraction") is not None:
        raise StudyProblem("display: give width_px or fraction, not both", field="display.fraction")
    if value.get("width_px") is not None:
        out["width_px"] = check_int(value["width_px"], "display.width_px", 32, 8192)
    if value.get("fraction") is not None:
        out["fraction"] = check_number(value["fraction"], "display.fraction", 0.1, 1.0)
    if value.get("fullscreen") is not None:
        out["fullscreen"] = check_bool(value["fullscreen"], "display.fullscreen")
    window = value.get("min_window")
    if window is not None:
        if isinstance(window, list | tuple) and len(window) == 2:
            window = {"width": window[0], "height": window[1]}
        check_keys(window, "display.min_window", ("width", "height"))
        out["min_window"] = {
            side: check_int(window.get(side), f"display.min_window.{side}", 100, 10_000) for side in ("width", "height")
        }
    if value.get("allow_phones") is not None:
        out["allow_phones"] = check_bool(value["allow_phones"], "display.allow_phones")
    return out


def check_redirect_url(value: Any, name: str = "completion.redirect_url") -> str:
    """An absolute http(s) URL without spaces or control characters (staff set it; never ``javascript:``)."""
    if not isinstance(value, str) or not 1 <= len(value) <= 2000:
        raise StudyProblem(f"{name} must be a URL of at most 2000 characters", field=name)
    if any(c.isspace() or ord(c) < 32 or ord(c) == 127 for c in value):
        raise StudyProblem(f"{name} must not contain spaces or control characters", field=name)
    parts = urlsplit(value)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        raise StudyProblem(f"{name} must start with https:// or http:// and name a host", field=name)
    return value


def check_completion(value: Any) -> dict[str, Any]:
    """The end: ``code`` (the completion code), ``redirect_url`` (may hold ``{code}``), ``failed_code``."""
    if value is None:
        return {}
    check_keys(value, "completion", COMPLETION_KEYS)
    out = {key: check_token(value[key], f"completion.{key}") for key in ("code", "failed_code") if value.get(key) is not None}
    if value.get("redirect_url") is not None:
        out["redirect_url"] = check_redirect_url(value["redirect_url"])
        if "{code}" in out["redirect_url"] and "code" not in out:
            raise StudyProblem("completion.redirect_url has {code} but completion.code is not set", field="completion.code")
    if "failed_code" in out and "code" not in out:
        raise StudyProblem("completion.failed_code needs completion.code too", field="completion.code")
    return out


def redirect_to(url: str | None, code: str | None) -> str | None:
    """The redirect URL with ``{code}`` replaced (URL-encoded); None without a URL."""
    if not url:
        return None
    return url.replace("{code}", quote(code or "", safe=""))


def check_open_link(value: Any, condition_names: list[str]) -> dict[str, Any] | None:
    """``{"cap": n, "quotas": {condition: n}}`` (both optional); None keeps the open link off."""
    if value is None:
        return None
    check_keys(value, "open_link", OPEN_LINK_KEYS)
    out: dict[str, Any] = {"cap": None, "quotas": {}}
    if value.get("cap") is not None:
        out["cap"] = check_int(value["cap"], "open_link.cap", 1, 100_000)
    quotas = value.get("quotas") or {}
    if not isinstance(quotas, dict):
        raise StudyProblem("open_link.quotas must be an object: {condition name: number}", field="open_link.quotas")
    for name, quota in quotas.items():
        if name not in condition_names:
            raise StudyProblem(f"open_link.quotas.{name}: no condition has this name", field=f"open_link.quotas.{name}")
        out["quotas"][name] = check_int(quota, f"open_link.quotas.{name}", 1, 100_000)
    return out


def check_comprehension(value: Any) -> dict[str, Any]:
    """Questions on the instructions: a list, or ``{"questions": [...], "max_attempts": n | null}``.

    Each question is ``{"question", "options": [...], "answer"}`` (the right
    option, by text or index). Normalised to ``{"questions": [... "answer":
    index], "max_attempts": n}`` (default 3; null: unlimited), or ``{}``.
    """
    if value is None or value == [] or value == {}:
        return {}
    attempts: Any = DEFAULT_ATTEMPTS
    if isinstance(value, dict):
        check_keys(value, "comprehension", ("questions", "max_attempts"))
        attempts = value.get("max_attempts", DEFAULT_ATTEMPTS)
        value = value.get("questions")
    if not isinstance(value, list) or not 1 <= len(value) <= MAX_QUESTIONS:
        raise StudyProblem(f"comprehension must be a list of 1-{MAX_QUESTIONS} questions", field="comprehension")
    questions = [_question(q, f"comprehension[{i}]") for i, q in enumerate(value)]
    if attempts is not None:
        attempts = check_int(attempts, "comprehension.max_attempts", 1, 100)
    return {"questions": questions, "max_attempts": attempts}


def _question(value: Any, name: str) -> dict[str, Any]:
    check_keys(value, name, QUESTION_KEYS)
    text = check_text(value.get("question"), f"{name}.question", max_len=1000)
    options = value.get("options")
    if not isinstance(options, list) or not 2 <= len(options) <= MAX_OPTIONS:
        raise StudyProblem(f"{name}.options must be a list of 2-{MAX_OPTIONS} answers", field=f"{name}.options")
    options = [check_text(o, f"{name}.options[{j}]", max_len=300) for j, o in enumerate(options)]
    if len(set(options)) != len(options):
        raise StudyProblem(f"{name}.options must all differ", field=f"{name}.options")
    answer = value.get("answer")
    if isinstance(answer, str) and answer.strip() in options:
        answer = options.index(answer.strip())
    if isinstance(answer, bool) or not isinstance(answer, int) or not 0 <= answer < len(options):
        raise StudyProblem(f"{name}.answer must be one of the options (its text or its index from 0)", field=f"{name}.answer")
    return {"question": text, "options": options, "answer": answer}


def check_conditions(value: Any, *, activity_names: list[str], frames_per_activity: int) -> list[dict[str, Any]]:
    """Between-subject conditions: ``[{"name", overrides...}]``; returns ``[{"name", "overrides"}]``.

    Overrides: ``time_limit_minutes``, ``trial_limit_seconds`` (null: none),
    ``instructions``, ``activities`` (a subset of the study's, by name) and
    ``frames_per_activity`` (at most the study's: the first frames of each
    activity's draw).
    """
    if value is None or value == []:
        return []
    if not isinstance(value, list) or not 2 <= len(value) <= MAX_CONDITIONS:
        raise StudyProblem(f"conditions must be a list of 2-{MAX_CONDITIONS} conditions (or none)", field="conditions")
    out, names = [], set()
    for i, item in enumerate(value):
        name = f"conditions[{i}]"
        check_keys(item, name, CONDITION_KEYS)
        label = check_token(item.get("name"), f"{name}.name")
        if label in names:
            raise StudyProblem(f"{name}.name: two conditions are called {label}", field=f"{name}.name")
        names.add(label)
        overrides: dict[str, Any] = {}
        if item.get("time_limit_minutes") is not None:
            overrides["time_limit_minutes"] = check_number(item["time_limit_minutes"], f"{name}.time_limit_minutes", 0.05, 7 * 24 * 60)
        if "trial_limit_seconds" in item:
            limit = item["trial_limit_seconds"]
            overrides["trial_limit_seconds"] = None if limit is None else check_int(limit, f"{name}.trial_limit_seconds", 1, 24 * 3600)
        if item.get("instructions") is not None:
            overrides["instructions"] = check_text(item["instructions"], f"{name}.instructions", max_len=MAX_TEXT)
        if item.get("activities") is not None:
            overrides["activities"] = _activity_subset(item["activities"], f"{name}.activities", activity_names)
        if item.get("frames_per_activity") is not None:
            overrides["frames_per_activity"] = check_int(
                item["frames_per_activity"], f"{name}.frames_per_activity", 1, frames_per_activity
            )
        out.append({"name": label, "overrides": overrides})
    return out


def _activity_subset(value: Any, name: str, activity_names: list[str]) -> list[str]:
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise StudyProblem(f"{name} must be a list of activity names", field=name)
    unknown = [v for v in value if v not in activity_names]
    if unknown:
        raise StudyProblem(f"{name}: {unknown[0]} is not one of the study's activities", field=name)
    return sorted(set(value))


@dataclass(frozen=True)
class Effective:
    """The settings in force for one participant (their condition's overrides on the study's)."""

    time_limit_s: int
    trial_limit_s: int | None
    instructions: str
    activities: list[str] | None  # None: all of the study's
    frames_per_activity: int


def effective(study: Study, condition: StudyCondition | None) -> Effective:
    overrides = condition.overrides if condition is not None else {}
    minutes = overrides.get("time_limit_minutes")
    return Effective(
        time_limit_s=max(1, round(minutes * 60)) if minutes is not None else study.time_limit_s,
        trial_limit_s=overrides["trial_limit_seconds"] if "trial_limit_seconds" in overrides else study.trial_limit_s,
        instructions=overrides.get("instructions", study.instructions),
        activities=overrides.get("activities"),
        frames_per_activity=overrides.get("frames_per_activity", study.frames_per_activity),
    )


def settings_of(participant: Participant) -> Effective:
    return effective(participant.study, participant.condition)
