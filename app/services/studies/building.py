"""Building a study: its settings, the frames it draws, editing, copying, deleting, opening and closing.

A study draws ``frames_per_activity`` frames at random from each chosen
activity's eligible frames (those with a finished ground truth, see
``app.services.ground_truth``), with ``random.Random(f"{seed}:{activity
name}")``, so the same seed over the same eligible frames draws the same
frames; practice frames are drawn from the eligible frames left, with
``random.Random(f"{seed}:practice")``, or named; catch frames are named with
their answer region. Participants, their codes, links and trial orders are
made by ``app.services.studies.recruiting``.
"""

import random
import secrets
from collections import defaultdict
from collections.abc import Iterable
from typing import Any

from sqlalchemy import func, update

from app.limits import MAX_ID
from app.extensions import db
from app.models import Activity, Frame, User
from app.models.studies import ActivityOrder, FrameKind, Participant, Study, StudyCondition, StudyFrame, StudyStatus
from app.services import ground_truth
from app.services.studies import protocol, recruiting
from app.services.studies.common import StudyProblem, check_int, check_keys, check_number, check_text
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
    "max_region_share": (SUPERPIXEL_DEFAULTS.max_region_share, float, 0.01, 1.0),
    "n_segments": (SUPERPIXEL_DEFAULTS.n_segments, int, 1, 10_000),
    "compactness": (SUPERPIXEL_DEFAULTS.compactness, float, 1e-3, 1e3),
    "scale": (SUPERPIXEL_DEFAULTS.scale, float, 1e-3, 1e5),
    "min_size": (SUPERPIXEL_DEFAULTS.min_size, int, 1, 100_000),
}
REFERENCE_WIDTH = egonet_clicks.REFERENCE_WIDTH
MAX_PRACTICE = 50
MAX_CATCH = 20
# What a duplicate copies from the study it copies (besides frames and conditions).
COPIED_COLUMNS = (
    "seed", "frames_per_activity", "time_limit_s", "trial_limit_s", "multiple_clicks", "sigma_px", "sigma_scaled",
    "superpixels", "instructions", "consent", "activity_order", "cap", "completion_code", "failed_code",
    "redirect_url", "comprehension", "display",
)  # fmt: skip

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


scaled_sigma = egonet_clicks.scaled_sigma


def sigma_for(study: Study, frame: Frame) -> float:
    """The click Gaussian's standard deviation for ``frame`` in its native pixels."""
    return scaled_sigma(frame.width) if study.sigma_scaled else study.sigma_px


def create_study(
    *,
    name: str,
    activity_ids: Iterable[int],
    frames_per_activity: int = 100,
    seed: int | None = None,
    time_limit_s: int = 3600,
    trial_limit_s: int | None = None,
    multiple_clicks: bool = True,
    sigma_px: float | None = None,
    superpixels: dict[str, Any] | None = None,
    instructions: str = DEFAULT_INSTRUCTIONS,
    consent: str = DEFAULT_CONSENT,
    practice_trials: int | list[int] | None = None,
    catch_trials: list[dict[str, Any]] | None = None,
    comprehension: list | dict | None = None,
    conditions: list[dict[str, Any]] | None = None,
    display: dict[str, Any] | None = None,
    open_link: dict[str, Any] | None = None,
    completion: dict[str, Any] | None = None,
    activity_order: str = ActivityOrder.SHUFFLED,
    created_by: User | None = None,
    study: Study | None = None,
    version: int | None = None,
) -> Study:
    """Create a study and draw its frames, in one transaction; or, given ``study``, redo that one.

    Args:
        name: Shown to the admin only.
        activity_ids: Activities to draw from; each must have at least
            ``frames_per_activity`` eligible frames.
        frames_per_activity: Frames drawn from each activity (the paper: 100).
        seed: Seed of the draws and of the participants' orders; a random
            one is drawn and recorded when None.
        time_limit_s: Session time limit (the paper: about an hour).
        trial_limit_s: Optional limit per trial.
        multiple_clicks: Several clicks per frame (then Next), or one
            click that answers at once.
        sigma_px: Click Gaussian's standard deviation in native pixels;
            None scales the paper's 60 px at 1280 px wide to each frame
            (``scaled_sigma``).
        superpixels: Options of ``egonet.clicks.superpixels`` (the method is recorded).
        instructions, consent: Texts shown to participants (plain text).
        practice_trials: Practice frames before the timed part: how many to
            draw from the remaining eligible frames, or their frame ids.
        catch_trials: Attention checks ``[{"frame", "position", "box"?}]``:
            a frame id, its place in the timed part (1-based) and the answer
            region in native pixels ``[x0, y0, x1, y1]`` (omitted: the
            frame's ground truth).
        comprehension, conditions, display, open_link, completion: see
            ``app.services.studies.protocol``.
        activity_order: ``shuffled``, or ``counterbalanced`` activity blocks.
        created_by: The admin creating it.
        study, version: Redo this study (same id, codes and links; frames
            drawn again, participants' trials rebuilt), refused once someone
            has entered or when ``version`` is not its current one.

    Raises:
        StudyProblem: naming the bad field, e.g. an activity with too few
            eligible frames.
    """
    columns, activity_ids, sigma_px = _checked_settings(
        name=name, activity_ids=activity_ids, frames_per_activity=frames_per_activity, seed=seed, time_limit_s=time_limit_s,
        trial_limit_s=trial_limit_s, multiple_clicks=multiple_clicks, sigma_px=sigma_px, activity_order=activity_order,
    )
    activities, eligible = _eligible_frames(activity_ids, frames_per_activity)
    names = [a.name for a in activities]
    condition_list = protocol.check_conditions(conditions, activity_names=names, frames_per_activity=frames_per_activity)
    link = protocol.check_open_link(open_link, [c["name"] for c in condition_list])
    columns |= _page_columns(superpixels, instructions, consent, comprehension, display, completion)
    columns["cap"] = link["cap"] if link else None
    study = _new_or_redone(study, columns, created_by=created_by, version=version, open_link=link is not None)
    _draw_study_frames(study, activities, eligible, practice_trials=practice_trials, catch_trials=catch_trials, sigma_px=sigma_px)
    _add_conditions(study, condition_list, quotas=link["quotas"] if link else {})
    if study.participants:
        recruiting.rebuild_participants(study)
    db.session.commit()
    return study


def _checked_settings(
    *, name: str, activity_ids: Iterable[int], frames_per_activity: int, seed: int | None, time_limit_s: int,
    trial_limit_s: int | None, multiple_clicks: bool, sigma_px: float | None, activity_order: str,
) -> tuple[dict[str, Any], list[int], float | None]:
    """The study's own settings checked, in the order the form shows them: its columns so far, the
    chosen activity ids and the click width (None: scaled to each frame)."""
    name = check_text(name or "", "name", max_len=200)
    activity_ids = sorted(set(activity_ids))
    if not activity_ids:
        raise StudyProblem("choose at least one activity", field="activities")
    check_int(frames_per_activity, "frames_per_activity", 1, 100_000)
    seed = new_seed() if seed is None else check_int(seed, "seed", 0, 2**31 - 1)
    check_int(time_limit_s, "time_limit_s", 1, 7 * 24 * 3600)
    if trial_limit_s is not None:
        check_int(trial_limit_s, "trial_limit_s", 1, 24 * 3600)
    if sigma_px is not None:
        sigma_px = check_number(sigma_px, "sigma_px", 0.5, 10_000)
    columns = dict(
        name=name,
        seed=seed,
        frames_per_activity=frames_per_activity,
        time_limit_s=time_limit_s,
        trial_limit_s=trial_limit_s,
        multiple_clicks=bool(multiple_clicks),
        activity_order=_activity_order(activity_order),
    )
    return columns, activity_ids, sigma_px


def _page_columns(superpixels, instructions, consent, comprehension, display, completion) -> dict[str, Any]:
    """What participants see: the click regions, the texts, the comprehension check, the display and the end, checked."""
    columns = dict(
        superpixels=check_superpixels(dict(superpixels or DEFAULT_SUPERPIXELS)),
        instructions=check_text(instructions or "", "instructions", max_len=protocol.MAX_TEXT, min_len=0),
        consent=check_text(consent or "", "consent", max_len=protocol.MAX_TEXT, min_len=0),
        comprehension=protocol.check_comprehension(comprehension),
        display=protocol.check_display(display),
    )
    completion = protocol.check_completion(completion)
    columns.update(completion_code=completion.get("code"), failed_code=completion.get("failed_code"),
                   redirect_url=completion.get("redirect_url"))
    return columns


def _new_or_redone(study: Study | None, columns: dict[str, Any], *, created_by: User | None, version: int | None,
                   open_link: bool) -> Study:
    """A new study with these columns; or ``study`` locked at ``version``, cleared and given them."""
    if study is None:
        study = Study(created_by=created_by, **columns)
        db.session.add(study)
    else:
        _lock_for_edit(study, version)
        _clear(study)
        for key, value in columns.items():
            setattr(study, key, value)
    if not open_link:
        study.open_link_token = None
    elif study.open_link_token is None:
        study.open_link_token = secrets.token_urlsafe(18)
    return study


def _draw_study_frames(study: Study, activities: list[Activity], eligible: dict[int, list[Frame]], *,
                       practice_trials: Any, catch_trials: Any, sigma_px: float | None) -> None:
    """The timed part's frames, then the practice and catch frames; the click width, scaled to the widest frame drawn when not given."""
    main = _draw_frames(study, activities, eligible)
    practice = _practice_frames(practice_trials, seed=study.seed, eligible=eligible, taken={f.id for f in main})
    catch = _catch_frames(catch_trials, main_count=len(main), taken={f.id for f in main} | {f.id for f in practice})
    _add_frames(study, practice, catch, start=len(main))
    study.sigma_scaled = sigma_px is None
    study.sigma_px = sigma_px if sigma_px is not None else scaled_sigma(max(f.width for f in main))


def _add_conditions(study: Study, conditions: list[dict[str, Any]], *, quotas: dict[str, int]) -> None:
    for position, item in enumerate(conditions, start=1):
        study.conditions.append(
            StudyCondition(position=position, name=item["name"], overrides=item["overrides"], quota=quotas.get(item["name"]))
        )
    db.session.flush()


def _activity_order(value: Any) -> ActivityOrder:
    try:
        return ActivityOrder(value)
    except ValueError:
        raise StudyProblem(f"activity_order must be one of {', '.join(ActivityOrder)}", field="activity_order") from None


def entered(study: Study) -> int:
    """How many of the study's participants have entered (consented, declined or ended)."""
    return db.session.execute(
        db.select(func.count())
        .select_from(Participant)
        .where(Participant.study_id == study.id, (Participant.consented_at.is_not(None)) | (Participant.finished_at.is_not(None)))
    ).scalar_one()


def _lock_for_edit(study: Study, version: int | None) -> None:
    """Take the study's row (its version grows) and refuse an edit of a stale version or after anyone entered."""
    db.session.commit()  # end any read transaction: the update below is the first statement of the edit's
    bumped = db.session.execute(
        update(Study).where(Study.id == study.id, Study.version == version).values(version=Study.version + 1)
    )
    if bumped.rowcount != 1:
        db.session.rollback()
        raise StudyProblem("someone else changed this study meanwhile; reload it and edit again", status=409, field="version")
    if entered(study):
        db.session.rollback()
        raise StudyProblem("a participant has already entered this study, so it can no longer be edited; duplicate it instead", status=409)
    db.session.refresh(study)


def _clear(study: Study) -> None:
    """Remove the study's drawn frames and conditions (and so its participants' trials) before it is drawn again."""
    for participant in study.participants:
        participant.condition = None
        participant.trials = []
    db.session.flush()
    study.frames = []
    study.conditions = []
    db.session.flush()


def _draw_frames(study: Study, activities: list[Activity], eligible: dict[int, list[Frame]]) -> list[Frame]:
    """Draw each activity's frames with its own ``random.Random(f"{seed}:{name}")``, numbered in order."""
    drawn_all = []
    for activity in activities:
        drawn = random.Random(f"{study.seed}:{activity.name}").sample(eligible[activity.id], study.frames_per_activity)
        for frame in drawn:
            drawn_all.append(frame)
            study.frames.append(StudyFrame(frame=frame, position=len(drawn_all)))
    return drawn_all


def _add_frames(study: Study, practice: list[Frame], catch: list[tuple[Frame, int, dict | None]], *, start: int) -> None:
    position = start
    for frame in practice:
        position += 1
        study.frames.append(StudyFrame(frame=frame, position=position, kind=FrameKind.PRACTICE))
    for frame, at, region in catch:
        position += 1
        study.frames.append(StudyFrame(frame=frame, position=position, kind=FrameKind.CATCH, catch_position=at, region=region))


def _practice_frames(value: Any, *, seed: int, eligible: dict[int, list[Frame]], taken: set[int]) -> list[Frame]:
    """Practice frames: ``n`` drawn (``random.Random(f"{seed}:practice")``) from the eligible frames not drawn, or these ids."""
    if value is None or value == 0 or value == []:
        return []
    if isinstance(value, list):
        if len(value) > MAX_PRACTICE:
            raise StudyProblem(f"practice_trials: at most {MAX_PRACTICE} frames", field="practice_trials")
        frames = [_frame(v, f"practice_trials[{i}]") for i, v in enumerate(value)]
        clash = [f.id for f in frames if f.id in taken]
        if clash or len({f.id for f in frames}) != len(frames):
            raise StudyProblem(f"practice_trials: frame {(clash or [frames[0].id])[0]} is used twice", field="practice_trials")
        return frames
    count = check_int(value, "practice_trials", 0, MAX_PRACTICE)
    left = [f for frames in eligible.values() for f in frames if f.id not in taken]
    if len(left) < count:
        raise StudyProblem(f"practice_trials: only {len(left)} eligible frames are left after the draw", field="practice_trials")
    return random.Random(f"{seed}:practice").sample(left, count)


def _frame(value: Any, name: str) -> Frame:
    frame = db.session.get(Frame, check_int(value, name, 1, MAX_ID))
    if frame is None:
        raise StudyProblem(f"{name}: there is no frame {value}", field=name)
    return frame


def _catch_frames(value: Any, *, main_count: int, taken: set[int]) -> list[tuple[Frame, int, dict | None]]:
    """Validate the catch trials: each frame (unused elsewhere), its place in the timed part and its answer region."""
    if value is None or value == []:
        return []
    if not isinstance(value, list) or len(value) > MAX_CATCH:
        raise StudyProblem(f"catch_trials must be a list of at most {MAX_CATCH} trials", field="catch_trials")
    out, positions = [], set()
    for i, item in enumerate(value):
        name = f"catch_trials[{i}]"
        check_keys(item, name, ("frame", "position", "box"))
        frame = _frame(item.get("frame"), f"{name}.frame")
        if frame.id in taken or frame.id in {f.id for f, _, _ in out}:
            raise StudyProblem(f"{name}.frame: frame {frame.id} is already in the study", field=f"{name}.frame")
        at = check_int(item.get("position"), f"{name}.position", 1, main_count + len(value))
        if at in positions:
            raise StudyProblem(f"{name}.position: two catch trials at position {at}", field=f"{name}.position")
        positions.add(at)
        region = None
        if item.get("box") is not None:
            region = {"box": _box(item["box"], frame, f"{name}.box")}
        elif frame.id not in ground_truth.ground_truths([frame.id]):
            raise StudyProblem(f"{name}: frame {frame.id} has no ground truth; give its answer region as a box", field=f"{name}.box")
        out.append((frame, at, region))
    return out


def _box(value: Any, frame: Frame, name: str) -> list[float]:
    if not isinstance(value, list) or len(value) != 4:
        raise StudyProblem(f"{name} must be [x0, y0, x1, y1] in the frame's pixels", field=name)
    x0, y0, x1, y1 = (check_number(v, name, -0.5, max(frame.width, frame.height)) for v in value)
    if not (x0 < x1 <= frame.width - 0.5 and y0 < y1 <= frame.height - 0.5):
        raise StudyProblem(f"{name} must lie in the {frame.width}x{frame.height} frame with x0 < x1 and y0 < y1", field=name)
    return [x0, y0, x1, y1]


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


def duplicate_study(study: Study, *, created_by: User | None = None) -> Study:
    """A new study with the same frames, conditions and settings (and seed), without participants, open."""
    copy = Study(
        **{column: getattr(study, column) for column in COPIED_COLUMNS},
        name=f"{study.name} (copy)"[:200],
        open_link_token=secrets.token_urlsafe(18) if study.open_link_token else None,
        created_by=created_by,
    )
    for sf in study.frames:
        copy.frames.append(
            StudyFrame(frame_id=sf.frame_id, position=sf.position, kind=sf.kind, catch_position=sf.catch_position, region=sf.region)
        )
    for c in study.conditions:
        copy.conditions.append(StudyCondition(position=c.position, name=c.name, overrides=dict(c.overrides), quota=c.quota))
    db.session.add(copy)
    db.session.commit()
    return copy


def delete_study(study: Study) -> None:
    """Delete a study nobody has entered, with its unused codes and their participant accounts.

    Raises:
        StudyProblem: 409 once a participant has entered (their data stay).
    """
    if entered(study):
        raise StudyProblem("participants have entered this study: it keeps their data and cannot be deleted; close it instead", status=409)
    users = [p.user for p in study.participants]
    db.session.delete(study)
    db.session.flush()
    for user in users:
        db.session.delete(user)
    db.session.commit()


def set_status(study: Study, status: StudyStatus | str) -> Study:
    """Open, pause or close a study: only an open study admits new participants; those already in finish."""
    try:
        study.status = StudyStatus(status)
    except ValueError:
        raise StudyProblem(f"status must be one of {', '.join(StudyStatus)}", field="status") from None
    db.session.commit()
    return study


def format_code(code: str) -> str:
    """``ABCD2345`` -> ``ABCD-2345`` (easier to read out and type)."""
    return f"{code[:4]}-{code[4:]}"

