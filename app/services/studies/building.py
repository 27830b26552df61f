"""Building a study: its settings, the frames it draws, its participants and their codes and links.

A study draws ``frames_per_activity`` frames at random from each chosen
activity's eligible frames (those with a finished ground truth, see
``app.services.ground_truth``), with ``random.Random(f"{seed}:{activity
name}")``, so the same seed over the same eligible frames draws the same
frames. Each participant gets every drawn frame once, shuffled with their own
``order_seed`` (derived from the study seed and their number). Every
participant gets an access code; some also a single-use sign-in link.
"""

import hashlib
import random
import secrets
from collections import defaultdict
from collections.abc import Iterable
from typing import Any

from sqlalchemy import func
from sqlalchemy.exc import IntegrityError

from app.extensions import db
from app.models import Activity, Frame, Role, User
from app.models.studies import EntryKind, Participant, Study, StudyFrame, Trial
from app.services import ground_truth
from app.services.studies.common import StudyProblem
from egonet import clicks as egonet_clicks
from egonet.clicks import SUPERPIXEL_DEFAULTS

SUPERPIXEL_OPTIONS = egonet_clicks.METHOD_OPTIONS
DEFAULT_SUPERPIXELS = {
    "method": SUPERPIXEL_DEFAULTS.method,
    **{name: getattr(SUPERPIXEL_DEFAULTS, name) for name in SUPERPIXEL_OPTIONS[SUPERPIXEL_DEFAULTS.method]},
    "max_side": SUPERPIXEL_DEFAULTS.max_side,
}
# Each option's default (egonet.clicks.SUPERPIXEL_DEFAULTS), type and accepted range.
OPTION_RULES = {
    "fine_regions": (SUPERPIXEL_DEFAULTS.fine_regions, int, 2, 20_000),
    "level": (SUPERPIXEL_DEFAULTS.level, float, 1e-3, 10.0),
    "n_segments": (SUPERPIXEL_DEFAULTS.n_segments, int, 1, 10_000),
    "compactness": (SUPERPIXEL_DEFAULTS.compactness, float, 1e-3, 1e3),
    "scale": (SUPERPIXEL_DEFAULTS.scale, float, 1e-3, 1e5),
    "min_size": (SUPERPIXEL_DEFAULTS.min_size, int, 1, 100_000),
}

DEFAULT_INSTRUCTIONS = (
    "You will see photos taken by a camera worn on a person's head during an everyday activity.\n\n"
    "In each photo, click the centre of every object the person is acting on: touching it (taking a cup) "
    "or deliberately looking at it (watching a TV). If there is no such object, answer None.\n\n"
    "Work quickly but carefully: the session has a time limit, shown at the top of the page."
)
DEFAULT_CONSENT = (
    "This study records where you click on each photo, how long you take, and when the window loses focus "
    "or changes size. Your answers are stored under a participant number, not your name. Taking part is "
    "voluntary and you may stop at any time by closing the window."
)

# Access codes: 8 characters without look-alikes (no 0/O, 1/I/L): 31^8, about 10^12.
CODE_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
CODE_LENGTH = 8


def new_seed() -> int:
    """A random seed for a new study (recorded with it)."""
    return secrets.randbelow(2**31)


def eligible_counts() -> list[tuple[Activity, int]]:
    """Every activity with its number of frames eligible for a study (finished ground truth)."""
    counts: dict[int, int] = defaultdict(int)
    for frame in ground_truth.labelled_frames():
        counts[frame.sequence.activity_id] += 1
    activities = db.session.execute(db.select(Activity).order_by(Activity.name)).scalars()
    return [(activity, counts[activity.id]) for activity in activities]


def check_superpixels(settings: dict[str, Any]) -> dict[str, Any]:
    """Validate superpixel settings (``egonet.clicks.superpixels`` options); return them normalised.

    Raises:
        StudyProblem: naming the bad option.
    """
    method = settings.get("method")
    if method not in SUPERPIXEL_OPTIONS:
        raise StudyProblem(f"superpixel method must be one of {', '.join(SUPERPIXEL_OPTIONS)}", field="superpixel_method")
    allowed = {"method", "max_side", *SUPERPIXEL_OPTIONS[method]}
    unknown = sorted(k for k, v in settings.items() if k not in allowed and v is not None)
    if unknown:
        raise StudyProblem(f"{', '.join(unknown)} does not apply to the {method} method", field=unknown[0])
    out: dict[str, Any] = {"method": method}
    for name in SUPERPIXEL_OPTIONS[method]:
        default, kind, low, high = OPTION_RULES[name]
        value = settings.get(name)
        if value is None:
            value = default
        if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
            raise StudyProblem(f"{name} must be a number in [{low}, {high}]", field=name)
        if kind is int and value != int(value):
            raise StudyProblem(f"{name} must be a whole number", field=name)
        out[name] = kind(value)
    max_side = settings.get("max_side", DEFAULT_SUPERPIXELS["max_side"])
    if max_side is not None:
        if isinstance(max_side, bool) or not isinstance(max_side, int | float) or max_side != int(max_side) or not 8 <= max_side <= 8192:
            raise StudyProblem("max_side must be a whole number in [8, 8192] (or empty for full resolution)", field="max_side")
        max_side = int(max_side)
    out["max_side"] = max_side
    return out


def create_study(
    *,
    name: str,
    activity_ids: Iterable[int],
    frames_per_activity: int = 100,
    seed: int | None = None,
    time_limit_s: int = 3600,
    trial_limit_s: int | None = None,
    multiple_clicks: bool = True,
    sigma_px: float = egonet_clicks.DEFAULT_SIGMA,
    superpixels: dict[str, Any] | None = None,
    instructions: str = DEFAULT_INSTRUCTIONS,
    consent: str = DEFAULT_CONSENT,
    created_by: User | None = None,
) -> Study:
    """Create a study and draw its frames, in one transaction.

    Args:
        name: Shown to the admin only.
        activity_ids: Activities to draw from; each must have at least
            ``frames_per_activity`` eligible frames.
        frames_per_activity: Frames drawn from each activity (the paper: 100).
        seed: Seed of the draw and of the participants' orders; a random one
            is drawn and recorded when None.
        time_limit_s: Session time limit (the paper: about an hour).
        trial_limit_s: Optional limit per trial.
        multiple_clicks: Several clicks per frame (then Next), or one
            click that answers at once.
        sigma_px: Click Gaussian's standard deviation in native pixels.
        superpixels: Options of ``egonet.clicks.superpixels``.
        instructions, consent: Texts shown to participants (plain text).
        created_by: The admin creating it.

    Raises:
        StudyProblem: naming the bad field, e.g. an activity with too few
            eligible frames.
    """
    name = (name or "").strip()
    if not 1 <= len(name) <= 200:
        raise StudyProblem("the name must have 1-200 characters", field="name")
    activity_ids = sorted(set(activity_ids))
    if not activity_ids:
        raise StudyProblem("choose at least one activity", field="activities")
    _check_int(frames_per_activity, "frames_per_activity", 1, 100_000)
    if seed is None:
        seed = new_seed()
    _check_int(seed, "seed", 0, 2**31 - 1)
    _check_int(time_limit_s, "time_limit_s", 1, 7 * 24 * 3600)
    if trial_limit_s is not None:
        _check_int(trial_limit_s, "trial_limit_s", 1, 24 * 3600)
    if isinstance(sigma_px, bool) or not isinstance(sigma_px, int | float) or not 0.5 <= sigma_px <= 10_000:
        raise StudyProblem("sigma must be a number of pixels in [0.5, 10000]", field="sigma_px")
    settings = check_superpixels(dict(superpixels or DEFAULT_SUPERPIXELS))
    activities, eligible = _eligible_frames(activity_ids, frames_per_activity)

    study = Study(
        name=name,
        seed=seed,
        frames_per_activity=frames_per_activity,
        time_limit_s=time_limit_s,
        trial_limit_s=trial_limit_s,
        multiple_clicks=bool(multiple_clicks),
        sigma_px=float(sigma_px),
        superpixels=settings,
        # Browsers send CRLF from a textarea; blank lines separate paragraphs on the pages.
        instructions=instructions.replace("\r\n", "\n").strip(),
        consent=consent.replace("\r\n", "\n").strip(),
        created_by=created_by,
    )
    _draw_frames(study, activities, eligible)
    db.session.add(study)
    db.session.commit()
    return study


def _draw_frames(study: Study, activities: list[Activity], eligible: dict[int, list[Frame]]) -> None:
    """Draw each activity's frames with its own ``random.Random(f"{seed}:{name}")``, numbered in order."""
    position = 0
    for activity in activities:
        drawn = random.Random(f"{study.seed}:{activity.name}").sample(eligible[activity.id], study.frames_per_activity)
        for frame in drawn:
            position += 1
            study.frames.append(StudyFrame(frame=frame, position=position))


def _eligible_frames(activity_ids: list[int], frames_per_activity: int) -> tuple[list[Activity], dict[int, list[Frame]]]:
    """The chosen activities by name, and each one's eligible frames; refuse an activity with too few."""
    activities = db.session.execute(db.select(Activity).where(Activity.id.in_(activity_ids)).order_by(Activity.name)).scalars().all()
    if len(activities) != len(activity_ids):
        raise StudyProblem("unknown activity", field="activities")
    eligible: dict[int, list[Frame]] = defaultdict(list)
    for frame in ground_truth.labelled_frames(activity_ids):
        eligible[frame.sequence.activity_id].append(frame)
    short = [f"{a.name} has {len(eligible[a.id])}" for a in activities if len(eligible[a.id]) < frames_per_activity]
    if short:
        raise StudyProblem(
            f"not enough eligible frames (finished ground truth) for {frames_per_activity} per activity: {'; '.join(short)}",
            field="frames_per_activity",
        )
    return activities, eligible


def _check_int(value: Any, name: str, low: int, high: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise StudyProblem(f"{name} must be a whole number in [{low}, {high}]", field=name)


def order_seed(study_seed: int, number: int) -> int:
    """The seed of participant ``number``'s trial order (31 bits, stable across platforms)."""
    digest = hashlib.sha256(f"{study_seed}:participant:{number}".encode()).digest()
    return int.from_bytes(digest[:4], "big") >> 1


def add_participants(study: Study, *, count: int, entry: EntryKind | str = EntryKind.CODE) -> list[Participant]:
    """Create ``count`` participants, each a user with the participant role and their trials.

    Every participant gets an access code; with ``entry="link"`` also a
    single-use sign-in link. Their trials cover every study frame in an
    order shuffled with their own ``order_seed``. One transaction.

    Raises:
        StudyProblem: for a bad count or entry kind, or when someone else
            added participants at the same moment (try again).
    """
    _check_int(count, "count", 1, 500)
    try:
        entry = EntryKind(entry)
    except ValueError:
        raise StudyProblem(f"entry must be one of {', '.join(e.value for e in EntryKind)}", field="entry") from None
    last = db.session.execute(db.select(func.max(Participant.number)).where(Participant.study_id == study.id)).scalar()
    frames = list(study.frames)
    created = []
    for number in range((last or 0) + 1, (last or 0) + 1 + count):
        seed = order_seed(study.seed, number)
        user = User(username=f"p-{study.id}-{number:03d}", role=Role.PARTICIPANT, password_hash=None)
        participant = Participant(
            study=study,
            user=user,
            number=number,
            entry=entry,
            code=_new_code(),
            link_token=secrets.token_urlsafe(32) if entry is EntryKind.LINK else None,
            order_seed=seed,
        )
        order = frames[:]
        random.Random(seed).shuffle(order)
        participant.trials = [Trial(study_frame=sf, position=i) for i, sf in enumerate(order, start=1)]
        db.session.add(participant)
        created.append(participant)
    try:
        db.session.commit()
    except IntegrityError:
        db.session.rollback()
        raise StudyProblem("participants were added at the same moment by someone else; try again", field="count") from None
    return created


def _new_code() -> str:
    return "".join(secrets.choice(CODE_ALPHABET) for _ in range(CODE_LENGTH))


def format_code(code: str) -> str:
    """``ABCD2345`` -> ``ABCD-2345`` (easier to read out and type)."""
    return f"{code[:4]}-{code[4:]}"

