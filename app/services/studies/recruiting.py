"""Recruiting: the open link, platforms' ids, places (cap and quotas), conditions, codes and trial orders.

Places: every participant whose account is active and who has not declined
holds a place in the study and in their condition. The open link admits a
newcomer only while the study is open, its places are under ``cap`` and
their condition's under its quota; codes and single-use links made by staff
are not limited. Each admission first updates the study's row
(``arrivals``): on PostgreSQL that row lock, on SQLite the write lock it
takes, makes concurrent admissions of one study wait for each other, so the
cap, the quotas and the balance of conditions hold under concurrent
arrivals.

Conditions are assigned balanced: a newcomer joins the condition with the
fewest places (the first of those tied). Trial order: practice trials
first, then the timed part in the participant's own order (shuffled with
their ``order_seed``, or with ``activity_order = counterbalanced`` in
activity blocks whose order follows a balanced Latin square over the
condition's participants), with the catch trials put in at their positions.
"""

import hashlib
import random
import re
import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field
from xml.sax.saxutils import escape as xml_escape

from flask import current_app
from sqlalchemy import func, or_, update
from sqlalchemy.exc import IntegrityError

from app.extensions import db
from app.models import Role, User
from app.models.studies import (
    ActivityOrder,
    EndReason,
    EntryKind,
    FrameKind,
    Participant,
    Study,
    StudyCondition,
    StudyFrame,
    StudyStatus,
    Trial,
)
from app.services.studies import protocol
from app.services.studies.common import TOKEN_PATTERN, StudyProblem, check_int, now

# Access codes: 8 characters without look-alikes (no 0/O, 1/I/L): 31^8, about 10^12.
CODE_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
CODE_LENGTH = 8
MAX_USER_AGENT = 512
# The recruiting platforms' URL parameters: (platform, the participant's id, the others kept with it).
PLATFORMS = (
    ("prolific", "PROLIFIC_PID", ("STUDY_ID", "SESSION_ID")),
    ("mturk", "workerId", ("assignmentId", "hitId", "turkSubmitTo")),
    ("external", "external_id", ()),
)
# The platforms' own id formats: a Prolific id is a 24-digit hexadecimal object id, an MTurk worker id
# (AWS's CustomerId) an A and then capital letters and digits, 64 characters at most.
ID_FORMATS = {
    "PROLIFIC_PID": (re.compile(r"[0-9a-fA-F]{24}"), "24 hexadecimal digits"),
    "workerId": (re.compile(r"A[A-Z0-9]{1,63}"), "an A followed by capital letters and digits, 64 characters at most"),
}
MTURK_PREVIEW = "ASSIGNMENT_ID_NOT_AVAILABLE"
"""MTurk's ``assignmentId`` while a worker previews a HIT (before accepting it)."""
# The platform's id of the participant's visit, given only to them with their id: a platform id alone is
# no credential, so a session resumes from the browser that first arrived, with this same visit id, or
# once staff released it (``RELEASED`` in ``external``: the next arrival binds a new browser).
VISIT_PARAMS = {"prolific": "SESSION_ID", "mturk": "assignmentId"}
RELEASED = "released_at"
# Where MTurk may send an ExternalQuestion's answers (its ``turkSubmitTo``); a deployment's
# ``MTURK_SUBMIT_HOSTS`` replaces the list (tests add a local stand-in that way, never by default).
MTURK_SUBMIT_HOSTS = ("https://workersandbox.mturk.com", "https://www.mturk.com")
MTURK_FRAME_HEIGHT = 800
"""The ExternalQuestion's FrameHeight in pixels: room for the open link's page (instructions, an example photo, the button)."""
PROLIFIC_QUERY = "PROLIFIC_PID={{%PROLIFIC_PID%}}&STUDY_ID={{%STUDY_ID%}}&SESSION_ID={{%SESSION_ID%}}"
"""What Prolific's study URL adds to the open link: Prolific fills these placeholders (MTurk fills none)."""

FULL = "This study is full: thank you for your interest."
PAUSED = "This study is paused and takes no new participants at the moment. Please try again later."
CLOSED = "This study is closed and takes no new participants."
ELSEWHERE = ("You started this study in another browser: please continue there. If you cannot, write to the "
             "researchers; they can let you continue here.")
WITHDRAWN = ("You withdrew from this study and your answers were deleted, as you asked, so it cannot be taken "
             "again. Thank you for your time.")


@dataclass
class Arrival:
    """Who arrives through the open link, from the platform's URL parameters."""

    platform: str | None = None
    external_id: str | None = None
    external: dict[str, str] = field(default_factory=dict)
    preview: bool = False  # an MTurk worker looking at the HIT before accepting it


def parse_arrival(args: Mapping[str, str]) -> Arrival:
    """The platform's parameters from a query string; others are ignored.

    Raises:
        StudyProblem: 400 naming the parameter when one is not 1-64 letters,
            digits, ``_``, ``.`` or ``-`` (a platform's id: not in its ``ID_FORMATS``;
            ``turkSubmitTo``: not one of ``mturk_submit_hosts()``).
    """
    arrival = Arrival()
    for platform, id_param, others in PLATFORMS:
        for param in (id_param, *others):
            value = args.get(param)
            if value is None or value == "":
                continue
            if param == "turkSubmitTo":
                if value.rstrip("/") not in mturk_submit_hosts():
                    raise StudyProblem(f"the link's turkSubmitTo must be one of {', '.join(mturk_submit_hosts())}", field=param)
                value = value.rstrip("/")
            elif param in ID_FORMATS:
                pattern, words = ID_FORMATS[param]
                if not pattern.fullmatch(value):
                    raise StudyProblem(f"the link's {param} must be {words}", field=param)
            elif not TOKEN_PATTERN.fullmatch(value):
                raise StudyProblem(f"the link's {param} must be 1-64 letters, digits, '_', '.' or '-'", field=param)
            if param == id_param and arrival.external_id is None:
                arrival.platform, arrival.external_id = platform, value
            else:
                arrival.external[param] = value
    arrival.preview = arrival.external.get("assignmentId") == MTURK_PREVIEW
    return arrival


def mturk_submit_hosts() -> tuple[str, ...]:
    return tuple(current_app.config.get("MTURK_SUBMIT_HOSTS", MTURK_SUBMIT_HOSTS))


def mturk_submit_url(participant: Participant) -> str | None:
    """Where an MTurk worker's page posts their assignment and completion code at the end (None for others)."""
    host, assignment = participant.external.get("turkSubmitTo"), participant.external.get("assignmentId")
    if participant.platform != "mturk" or host not in mturk_submit_hosts() or not assignment:
        return None
    return host + "/mturk/externalSubmit"


def platform_urls(open_link: str) -> dict[str, str]:
    """What each platform is given: Prolific's study URL, MTurk's ExternalURL and its ExternalQuestion XML.

    MTurk fills no placeholders in an ExternalURL: it appends its own
    ``assignmentId``, ``hitId``, ``turkSubmitTo`` and ``workerId`` (none in a
    preview) to the URL as given, so its URL is the bare open link.

    Example:
        >>> platform_urls("https://a.example/s/o/T")["mturk_url"]
        'https://a.example/s/o/T'
    """
    question = (
        '<ExternalQuestion xmlns="http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/2006-07-14/ExternalQuestion.xsd">\n'
        f"  <ExternalURL>{xml_escape(open_link)}</ExternalURL>\n"
        f"  <FrameHeight>{MTURK_FRAME_HEIGHT}</FrameHeight>\n"
        "</ExternalQuestion>\n"
    )
    return {"prolific_url": f"{open_link}?{PROLIFIC_QUERY}", "mturk_url": open_link, "mturk_question": question}


def example_frame(study: Study) -> StudyFrame | None:
    """The frame an MTurk preview shows (the first practice frame, else the first of the study)."""
    return next(iter(study.frames_of(FrameKind.PRACTICE) or study.frames), None)


def open_link_study(token: str) -> Study:
    """The study whose open link this is. Raises StudyProblem 404 for an unknown link (or one switched off)."""
    study = None
    if TOKEN_PATTERN.fullmatch(token or ""):
        study = db.session.execute(db.select(Study).filter_by(open_link_token=token)).scalar_one_or_none()
    if study is None:
        raise StudyProblem("this study link does not exist", status=404)
    return study


def by_external_id(study: Study, external_id: str | None) -> Participant | None:
    if external_id is None:
        return None
    return db.session.execute(db.select(Participant).filter_by(study_id=study.id, external_id=external_id)).scalar_one_or_none()


def _holding(*, open_link: bool = True):
    """The participants who hold a place: active accounts that did not decline, pilots left out; with
    ``open_link``, only those who came through the open link (the cap and the quotas are its places:
    lab codes and single-use links, made by staff, take none)."""
    query = (
        db.select(Participant)
        .join(User, Participant.user)
        .where(User.active.is_(True), or_(Participant.end_reason.is_(None), Participant.end_reason != EndReason.DECLINED))
        .where(Participant.pilot.is_(False))
    )
    return query.where(Participant.entry == EntryKind.OPEN) if open_link else query


def places_taken(study: Study) -> int:
    """The open link's places taken (see ``_holding``)."""
    query = _holding().where(Participant.study_id == study.id).with_only_columns(func.count())
    return db.session.execute(query).scalar_one()


def condition_places(study: Study, *, open_link: bool = True) -> dict[int, int]:
    """Places taken per condition id: the open link's (for its quotas), or everyone's (to balance the conditions)."""
    query = (
        _holding(open_link=open_link)
        .where(Participant.study_id == study.id, Participant.condition_id.is_not(None))
        .with_only_columns(Participant.condition_id, func.count())
        .group_by(Participant.condition_id)
    )
    return dict(db.session.execute(query).all())


def availability(study: Study) -> str | None:
    """Why the open link takes nobody now (``paused``, ``closed``, ``full``), or None."""
    if study.status is not StudyStatus.OPEN:
        return study.status.value
    if study.cap is not None and places_taken(study) >= study.cap:
        return "full"
    if study.conditions and not _open_conditions(study, condition_places(study)):
        return "full"
    return None


def refusal(reason: str) -> StudyProblem:
    """The polite refusal of the open link: 409 full, paused or elsewhere (another browser's session), 410 closed."""
    text = {"full": FULL, "paused": PAUSED, "closed": CLOSED, "elsewhere": ELSEWHERE, "withdrawn": WITHDRAWN}[reason]
    return StudyProblem(text, status=410 if reason in ("closed", "withdrawn") else 409, reason=reason)


def _open_conditions(study: Study, counts: dict[int, int]) -> list[StudyCondition]:
    return [c for c in study.conditions if c.quota is None or counts.get(c.id, 0) < c.quota]


def _lock(study: Study) -> None:
    """Start the transaction with the update that every admission to this study makes first (see module doc)."""
    db.session.commit()
    db.session.execute(update(Study).where(Study.id == study.id).values(arrivals=Study.arrivals + 1))
    db.session.refresh(study)


def may_resume(participant: Participant, arrival: Arrival, *, same_browser: bool) -> bool:
    """Whether ``arrival`` may continue ``participant``'s session (see ``VISIT_PARAMS``)."""
    param = VISIT_PARAMS.get(participant.platform)
    visit = arrival.external.get(param) if param else None
    return same_browser or (visit is not None and visit == participant.external.get(param)) or RELEASED in participant.external


def returning(participant: Participant, arrival: Arrival, *, same_browser: bool) -> str | None:
    """Why a known participant's arrival may not go on (``withdrawn``, ``elsewhere``: see ``refusal``), or None."""
    if participant.withdrawn_at is not None:
        return "withdrawn"
    return None if arrival.preview or may_resume(participant, arrival, same_browser=same_browser) else "elsewhere"


def resume(participant: Participant, arrival: Arrival, *, same_browser: bool) -> Participant:
    """The participant again, their platform's parameters now this visit's (a new MTurk assignment, say).

    Raises:
        StudyProblem: 410 (``reason`` withdrawn) or 409 (``elsewhere``) when the arrival may not resume them (``returning``).
    """
    reason = returning(participant, arrival, same_browser=same_browser)
    if reason is not None:
        raise refusal(reason)
    participant.external = {k: v for k, v in participant.external.items() if k != RELEASED} | arrival.external
    db.session.commit()
    return participant


def release(participant: Participant) -> None:
    """Let the next arrival with the participant's id continue in a new browser; browsers signed in now are signed out."""
    participant.external = {**participant.external, RELEASED: now().isoformat()}
    participant.user.end_sessions()
    db.session.commit()


def admit(study: Study, arrival: Arrival, *, user_agent: str | None = None, same_browser: bool = False) -> Participant:
    """The participant arriving through the open link: the one with this external id (``resume``), or a new one.

    A newcomer needs the study open and a free place within the cap and a
    condition's quota; they get a condition (balanced), a code and their
    trials, in one transaction. ``same_browser``: this browser is signed in
    as the participant with this external id.

    Raises:
        StudyProblem: 409 (``reason`` full or paused) or 410 (closed) for a
            newcomer who cannot be admitted; 409 for an MTurk preview, and
            (``reason`` elsewhere) for a known id from another browser.
    """
    if arrival.preview:
        raise StudyProblem("accept the HIT first, then open the study", status=409, reason="preview")
    known = by_external_id(study, arrival.external_id)
    if known is not None:
        return resume(known, arrival, same_browser=same_browser)
    _lock(study)
    try:
        reason = availability(study)
        if reason is not None:
            raise refusal(reason)
        everyone = condition_places(study, open_link=False)
        condition = _balanced(_open_conditions(study, condition_places(study)), everyone) if study.conditions else None
        participant = _new_participant(
            study, entry=EntryKind.OPEN, condition=condition, user_agent=user_agent, arrival=arrival
        )
        db.session.add(participant)
        db.session.commit()
    except StudyProblem:
        db.session.rollback()
        raise
    except IntegrityError:  # the same external id arrived twice at once: the other request made them
        db.session.rollback()
        known = by_external_id(study, arrival.external_id)
        if known is None:
            raise
        return resume(known, arrival, same_browser=False)
    return participant


def _balanced(conditions: list[StudyCondition], counts: dict[int, int]) -> StudyCondition:
    return min(conditions, key=lambda c: (counts.get(c.id, 0), c.position))


def add_participants(
    study: Study, *, count: int, entry: EntryKind | str = EntryKind.CODE, pilot: bool = False
) -> list[Participant]:
    """Create ``count`` participants (codes; with ``entry="link"`` also single-use links), each with their trials.

    Conditions are assigned balanced; staff's codes are not limited by the
    cap or the quotas. ``pilot``: staff trying the study (see ``Participant``). One transaction.

    Raises:
        StudyProblem: for a bad count or entry kind, or when someone else
            added participants at the same moment (try again).
    """
    check_int(count, "count", 1, 500)
    try:
        entry = EntryKind(entry)
    except ValueError:
        raise StudyProblem(f"entry must be one of {', '.join(e.value for e in EntryKind)}", field="entry") from None
    if entry is EntryKind.OPEN:
        raise StudyProblem("participants of the open link arrive by themselves", field="entry")
    _lock(study)
    counts = condition_places(study, open_link=False)
    created = []
    for _ in range(count):
        condition = _balanced(study.conditions, counts) if study.conditions else None
        if condition is not None:
            counts[condition.id] = counts.get(condition.id, 0) + 1
        participant = _new_participant(study, entry=entry, condition=condition, number=_next_number(study, created))
        participant.pilot = bool(pilot)
        db.session.add(participant)
        created.append(participant)
    try:
        db.session.commit()
    except IntegrityError:
        db.session.rollback()
        raise StudyProblem("participants were added at the same moment by someone else; try again", field="count") from None
    return created


def _next_number(study: Study, created: list[Participant]) -> int:
    if created:
        return created[-1].number + 1
    last = db.session.execute(db.select(func.max(Participant.number)).where(Participant.study_id == study.id)).scalar()
    return (last or 0) + 1


def _new_participant(
    study: Study,
    *,
    entry: EntryKind,
    condition: StudyCondition | None,
    number: int | None = None,
    user_agent: str | None = None,
    arrival: Arrival | None = None,
) -> Participant:
    number = number or _next_number(study, [])
    seed = order_seed(study.seed, number)
    index = _index_in(study, condition)  # before the new participant joins the study (autoflush)
    participant = Participant(
        study=study,
        user=User(username=f"p-{study.id}-{number:03d}", role=Role.PARTICIPANT, password_hash=None),
        number=number,
        entry=entry,
        code=new_code(),
        link_token=secrets.token_urlsafe(32) if entry is EntryKind.LINK else None,
        order_seed=seed,
        condition=condition,
        user_agent=(user_agent or "")[:MAX_USER_AGENT] or None,
        external_id=arrival.external_id if arrival else None,
        platform=arrival.platform if arrival else None,
        external=dict(arrival.external) if arrival else {},
    )
    with db.session.no_autoflush:
        participant.trials = build_trials(study, condition, seed=seed, index=index)
    return participant


def _index_in(study: Study, condition: StudyCondition | None) -> int:
    """How many participants the condition (or the study, without conditions) already has: the Latin square's row."""
    query = db.select(func.count()).select_from(Participant).where(Participant.study_id == study.id)
    if condition is not None:
        query = query.where(Participant.condition_id == condition.id)
    return db.session.execute(query).scalar_one()  # autoflush counts those added in this transaction


def rebuild_participants(study: Study) -> None:
    """Give a redrawn study's participants (none has entered) balanced conditions and new trials; the caller commits."""
    counts: dict[int, int] = {}
    seen: dict[int | None, int] = {}
    for participant in study.participants:
        condition = _balanced(study.conditions, counts) if study.conditions else None
        key = condition.position if condition is not None else None
        if condition is not None:
            counts[condition.id] = counts.get(condition.id, 0) + 1
        participant.condition = condition
        participant.trials = build_trials(study, condition, seed=participant.order_seed, index=seen.get(key, 0))
        seen[key] = seen.get(key, 0) + 1


def build_trials(study: Study, condition: StudyCondition | None, *, seed: int, index: int) -> list[Trial]:
    """A participant's trials: practice, then the timed part in their order with the catch trials at their places."""
    settings = protocol.effective(study, condition)
    blocks: dict[str, list[StudyFrame]] = {}
    for sf in study.frames_of(FrameKind.MAIN):  # activity by activity (by name), each in its draw order
        blocks.setdefault(sf.frame.sequence.activity.name, []).append(sf)
    names = [n for n in blocks if settings.activities is None or n in settings.activities]
    chosen = {n: blocks[n][: settings.frames_per_activity] for n in names}
    rng = random.Random(seed)
    if study.activity_order is ActivityOrder.COUNTERBALANCED:
        rows = balanced_latin_square(len(names))
        order = []
        for block in rows[index % len(rows)]:
            frames = chosen[names[block]][:]
            rng.shuffle(frames)
            order += frames
    else:
        order = [sf for n in names for sf in chosen[n]]
        rng.shuffle(order)
    for sf in sorted(study.frames_of(FrameKind.CATCH), key=lambda sf: sf.catch_position):
        order.insert(min(sf.catch_position - 1, len(order)), sf)
    order = study.frames_of(FrameKind.PRACTICE) + order
    return [Trial(study_frame=sf, position=i) for i, sf in enumerate(order, start=1)]


def balanced_latin_square(n: int) -> list[list[int]]:
    """Orders of ``n`` blocks where each block comes at each place, and after each other block, equally often.

    Williams' design: rows ``r`` of ``0, 1, n-1, 2, n-2, ...`` shifted by
    ``r``; for odd ``n`` the reversed rows are added (2n rows).
    """
    first = [(j + 1) // 2 if j % 2 else (n - j // 2) % n for j in range(n)]
    rows = [[(k + r) % n for k in first] for r in range(n)]
    return rows + [row[::-1] for row in rows] if n % 2 else rows


def order_seed(study_seed: int, number: int) -> int:
    """The seed of participant ``number``'s trial order (31 bits, stable across platforms)."""
    digest = hashlib.sha256(f"{study_seed}:participant:{number}".encode()).digest()
    return int.from_bytes(digest[:4], "big") >> 1


def new_code() -> str:
    return "".join(secrets.choice(CODE_ALPHABET) for _ in range(CODE_LENGTH))


def set_active(participant: Participant, active: bool) -> Participant:
    """Deactivate a participant (their code, link and session stop working; their place is freed) or activate them again."""
    if active and participant.withdrawn_at is not None:
        raise StudyProblem(f"{participant.label} has withdrawn: their data is gone", status=409)
    participant.user.active = bool(active)
    participant.user.end_sessions()
    db.session.commit()
    return participant
