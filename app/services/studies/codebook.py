"""The codebook: every column of every file a study exports, with its unit and convention.

The one source of the column lists (``exports`` and the per-frame scores
take their headers from here) and of their descriptions. ``markdown()`` is
written into the export as ``CODEBOOK.md`` and is the section "Codebook" of
``docs/studies.md``; a test keeps the two identical and checks every
exported header against it. After changing a description, rewrite the
docs' section with ``python -c "from app.services.studies.codebook import
rewrite_docs; rewrite_docs('docs/studies.md')"``.
"""

from dataclasses import dataclass
from pathlib import Path

from egonet.clicks import SUPERPIXEL_DEFAULTS


@dataclass(frozen=True)
class Table:
    """One exported file: what it holds (one line per what) and its columns, in order, with their meanings.

    ``patterns`` are columns repeated per scored row, ``<row>`` standing for
    the row's key (per-frame scores only).
    """

    name: str
    about: str
    columns: dict[str, str]
    patterns: dict[str, str] | None = None


_WHO = {
    "study_id": "The study's id.",
    "participant": "The participant's label in the study (`P01`, …).",
}
_PLATFORM = {
    "external_id": "The id their platform gave (Prolific's `PROLIFIC_PID`, MTurk's `workerId`, or `external_id`); empty for lab codes.",
    "condition": "Their between-subject condition's name; empty in a study without conditions.",
    "pilot": "`True` for a pilot (staff trying the study): kept in every file, marked here, never in a mean, a score or a count of places.",
}
_TRIAL = {
    "trial_id": "The trial's id (unique across studies).",
    "position": "The trial's place in this participant's sequence, from 1 (practice trials first).",
}
_KIND = {"kind": "`main` (timed and scored), `practice` (never scored) or `catch` (an attention check, never scored as data)."}
_TIME = "ISO 8601 in UTC, by the server's clock"
_CLICK_XY = (
    "in native pixels of the frame, {axis}; pixel centres are at integer coordinates, so the frame spans "
    "[-0.5, {size} - 0.5] and the pixel (row r, column c) covers [c - 0.5, c + 0.5) x [r - 0.5, r + 0.5)"
)

TRIALS = Table("trials.csv", "One line per trial of every participant, in participant then trial order.", {
    **_WHO,
    "participant_id": "The participant's id (unique across studies).",
    **{k: _PLATFORM[k] for k in ("external_id", "condition", "pilot")},
    **_TRIAL,
    **_KIND,
    "activity": "The frame's activity.",
    "frame_id": "The frame's id in this installation.",
    "frame_source": "The frame's file name as imported (stable across installations).",
    "frame_width": "The frame's native width, px.",
    "frame_height": "The frame's native height, px.",
    "outcome": "`clicked`, `none` (answered that there is no action-object), `timed_out` (the trial's limit ran out; the clicks made "
               "until then count), `expired` (no answer arrived in time), `not_reached` (the session ended first) or `pending`.",
    "clicks": "Number of clicks kept (undone clicks are not counted).",
    "hit": "Whether a click fell on the true action-object (its ground-truth mask, or a catch trial's answer box); empty without an "
           "answer or a truth to compare with.",
    "rt_ms": "Milliseconds from the first painting of the photo to the answer, by the browser's clock; a reload does not restart it "
             "(the time shown before, by the server's clock, is added). Empty without an answer.",
    "shown_at": f"When the server first served the trial, {_TIME}.",
    "submitted_at": f"When the answer arrived, {_TIME}.",
    "server_ms": "submitted_at - shown_at in milliseconds: rt_ms plus the network's and the page's delays.",
    "window_width": "The browser window's inner width at the answer, CSS px.",
    "window_height": "The browser window's inner height at the answer, CSS px.",
    "display_width": "The photo's displayed width at the answer, CSS px (native width x this / frame_width = CSS px per native px).",
    "display_height": "The photo's displayed height at the answer, CSS px.",
    "pixel_ratio": "The browser's devicePixelRatio at the answer (device px per CSS px).",
    "sigma_px": "The click Gaussian's standard deviation for this frame, native px.",
    "events": "Number of browser events logged during the trial (events.csv).",
})

CLICKS = Table("clicks.csv", "One line per click kept, in participant, trial and click order.", {
    **_WHO,
    **{k: _PLATFORM[k] for k in ("external_id", "condition", "pilot")},
    **_TRIAL,
    **_KIND,
    "frame_id": TRIALS.columns["frame_id"],
    "click": "The click's place in the trial, from 1.",
    "x": "Horizontal position " + _CLICK_XY.format(axis="x the column, from the left", size="frame_width") + ".",
    "y": "Vertical position " + _CLICK_XY.format(axis="y the row, from the top", size="frame_height") + ".",
    "inside": "Whether this click fell on the true action-object (as `hit` in trials.csv); empty without a truth.",
    "rt_ms": "Milliseconds from the first painting of the photo to this click (as the trial's rt_ms).",
    "received_at": f"When the answer holding the click arrived, {_TIME}.",
})

EVENTS = Table("events.csv", "One line per browser event during a trial, in participant, trial and event order.", {
    **_WHO,
    **{k: _PLATFORM[k] for k in ("external_id", "condition", "pilot")},
    **_TRIAL,
    "frame_id": TRIALS.columns["frame_id"],
    "event": "The event's place in the trial, from 1.",
    "kind": "`blur`, `focus`, `visibility`, `resize`, `undo`, `fullscreen` (from the browser) or `reload` (the server served the trial "
            "again).",
    "client_ms": "Milliseconds from the photo's first painting, by the browser's clock (as rt_ms); empty for `reload`.",
    "server_at": f"When the server received the event (with the answer) or served the reload, {_TIME}.",
    "detail": "JSON: `{\"state\": \"hidden\"|\"visible\"}` for visibility, `{\"state\": \"entered\"|\"exited\"}` for fullscreen, "
              "`{\"width\", \"height\"}` (CSS px) for resize, `{\"x\", \"y\"}` (native px) of the removed click for undo.",
})

PARTICIPANTS = Table("participants.csv", "One line per participant (withdrawn ones included, their data deleted), in label order.", {
    **_WHO,
    "participant_id": TRIALS.columns["participant_id"],
    "code": "Their code, as shown to them (`ABCD-2345`); typed with or without the dash.",
    "entry": "How they came: `code` (a lab code), `link` (a single-use link) or `open` (the study's open link).",
    "platform": "`prolific`, `mturk` or `external` for open-link arrivals with a platform id; empty otherwise.",
    "external_id": _PLATFORM["external_id"],
    "external": "JSON of the other platform parameters they arrived with (Prolific's STUDY_ID and SESSION_ID, MTurk's assignmentId "
                "and hitId); empty when none.",
    "condition": _PLATFORM["condition"],
    "pilot": _PLATFORM["pilot"],
    "status": "`not started`, `consented`, `practice`, `ready`, `running`, `time up`, `completed`, `declined`, `screened out`, "
              "`deactivated` or `withdrawn`.",
    "active": "Whether their code and session still work (`False` after deactivation or withdrawal).",
    "checks_passed": "`True` when every check was passed, `False` when one failed, empty while one is pending and for a withdrawn "
                     "participant (their answers are deleted).",
    "comprehension": "The comprehension questions: `passed`, `failed`, `pending` or `none` (the study has none); empty when withdrawn.",
    "catch_passed": "Catch trials passed (a click in the answer region); empty when withdrawn.",
    "catch_total": "Catch trials in their sequence; empty when withdrawn.",
    "completion_code": "The code they were given at the end (the study's, or its failed_code); empty if none.",
    "consented_at": f"When they consented, {_TIME}.",
    "started_at": f"When the timed part began (their clock started), {_TIME}.",
    "finished_at": f"When the session ended, {_TIME}.",
    "end_reason": "`completed`, `time_up`, `declined` or `screened_out`; empty while running.",
    "answered": "Trials of the timed part (main and catch) with an answer.",
    "total": "Trials of the timed part (main and catch).",
    "user_agent": "The browser's user agent string.",
    "screen_width": "The screen's width when the study page loaded, CSS px.",
    "screen_height": "The screen's height, CSS px.",
    "window_width": "The window's inner width when the study page loaded, CSS px.",
    "window_height": "The window's inner height, CSS px.",
    "pixel_ratio": "devicePixelRatio when the page loaded.",
    "time_zone": "The browser's IANA time zone.",
    "touch": "Whether the device reported a touch screen.",
    "withdrawn_at": f"When staff withdrew them and deleted their data, {_TIME}; empty otherwise.",
    "withdrawn_by": "The staff user who did it; empty otherwise.",
})

MANIFEST = Table("manifest.csv", "In masks.zip: one line per soft-mask PNG, each participant's trials first, then each frame's mean.", {
    "file": "The PNG's path in the zip: `P01/0001-frame12.png` (participant, trial position, frame id) or `mean/frame12.png`. "
            "16-bit grayscale, value = mask x 65535 (rounded).",
    "participant": "The participant's label, or `mean`.",
    "pilot": "As in trials.csv (empty for a mean).",
    "position": "The trial's position (empty for a mean).",
    "kind": "The trial's or the frame's kind (`main`, `practice`, `catch`).",
    "frame_id": TRIALS.columns["frame_id"],
    "activity": TRIALS.columns["activity"],
    "frame_source": TRIALS.columns["frame_source"],
    "outcome": "The trial's outcome (`clicked`, `none`, `timed_out`; empty for a mean). A `none` answer's mask is all zeros.",
    "participants": "For a mean: how many participants' masks it averages (pilots left out); empty for a trial.",
    "sigma_px": "The click Gaussian's standard deviation used, native px.",
    "hit_cap": f"For a trial: whether a click fell on a region that stands where the region cap (no region over "
               f"max_region_share of the frame, {SUPERPIXEL_DEFAULTS.max_region_share:g} by default) split a larger one; "
               "for a mean: how many of its trials did.",
})

PER_FRAME = Table(
    "per-frame-<activity>.csv",
    "From the Scores page's per-frame view (`/scores/frames.csv`): one line per frame of one activity, each row of the table with "
    "its own scores on it.",
    {
        "frame_id": TRIALS.columns["frame_id"],
        "frame": "`sequence #index` of the frame.",
        "activity": TRIALS.columns["activity"],
        "action-object pixels": "Number of pixels of the frame's ground-truth action-object mask, at the native size (0: none).",
        "empty frames policy": "How a frame with 0 action-object pixels is scored (`leave-out`: blank, not scored).",
    },
    {
        "<row> best F": "The row's best F-measure on this frame over the thresholds, 4 decimals; blank where the row has not got "
                        "the frame.",
        "<row> threshold": "The threshold giving that best F, 2 decimals.",
        "<row> AP": "The row's average precision on this frame; blank for people (a soft mask from clicks has no ranking to average).",
    },
)

TABLES = (TRIALS, CLICKS, EVENTS, PARTICIPANTS, MANIFEST, PER_FRAME)

OTHER_FILES = {
    "study.json": "Everything above in one document: the study's settings, its frames, and each participant with their trials, "
                  "clicks and events (the same values and units as the CSV columns of the same names).",
    "definition.json": "The study's definition file (docs/studies.md, \"Running a study online\"): creating it again over the same "
                       "data draws the same frames.",
    "masks.zip": "The soft masks (`P01/…png`, `mean/…png`, manifest.csv) with what recomputes them: clicks.csv, `labels/frame<id>.npz` "
                 "and regions.json (below), and this codebook as CODEBOOK.md.",
    "labels/frame<id>.npz": "The frame's region labels as used for every mask of it: numpy's compressed `.npz` with one array "
                            "`labels`, uint16 (or int32) (frame_height, frame_width), ids 0..n-1, row-major like the image.",
    "regions.json": "How the labels were made: `code_version` and `libraries` (the versions of numpy, SciPy, scikit-image and "
                    "OpenCV), `function` and `settings` (the call that regenerates them from the "
                    "frame's RGB image), `max_region_share`, `trials_hit_cap`, and per frame: `frame_id`, `file`, `width`, `height`, "
                    "`sigma_px`, `regions` (how many) and `capped` (the ids of regions that stand where the cap split a larger one).",
}


def markdown() -> str:
    """The codebook as Markdown (CODEBOOK.md in the export; the docs' "Codebook" section)."""
    lines = [
        "Every column of every file a study exports. Times are ISO 8601 in UTC by the server's clock; durations in "
        "milliseconds; sizes in pixels (native px of the frame, or CSS px of the browser where said). Booleans are `True`/`False`, "
        "a missing value is an empty cell. Click coordinates: x is the column, y the row, in native pixels with pixel centres at "
        "integer coordinates (the top-left corner of the frame is (-0.5, -0.5)).",
        "",
    ]
    for table in TABLES:
        lines += [f"### {table.name}", "", table.about, "", "| Column | Meaning |", "| --- | --- |"]
        lines += [f"| `{name}` | {text} |" for name, text in {**table.columns, **(table.patterns or {})}.items()]
        lines.append("")
    lines += ["### Other files", "", "| File | What it holds |", "| --- | --- |"]
    lines += [f"| `{name}` | {text} |" for name, text in OTHER_FILES.items()]
    return "\n".join(lines) + "\n"


BEGIN, END = "<!-- codebook: generated by app/services/studies/codebook.py -->", "<!-- end of codebook -->"


def docs_section(text: str) -> str:
    """The codebook section of a docs page (between the markers)."""
    return text[text.index(BEGIN) + len(BEGIN) : text.index(END)].strip("\n") + "\n"


def rewrite_docs(path: str | Path) -> None:
    """Put ``markdown()`` between the markers of the docs page at ``path``."""
    path = Path(path)
    text = path.read_text()
    head, tail = text[: text.index(BEGIN) + len(BEGIN)], text[text.index(END) :]
    path.write_text(f"{head}\n{markdown()}\n{tail}")
