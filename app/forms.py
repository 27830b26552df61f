"""The base of every HTML form in the app, and the studies' forms.

Flask-WTF also fills forms from a JSON body, where a number or a nested
value breaks the fields (a 500). Our forms are HTML forms: they read the
form data only (a JSON body never reaches a form's view:
``app.validation.check_request`` answers it with 415), and a POST without
fields leaves them empty (a 400 naming the missing fields).
"""

import json
from typing import Any

from flask import request
from flask_wtf import FlaskForm
from flask_wtf.file import FileRequired
from flask_wtf.form import _Auto
from werkzeug.datastructures import CombinedMultiDict, ImmutableMultiDict
from wtforms import (
    BooleanField,
    FileField,
    FloatField,
    HiddenField,
    IntegerField,
    SelectChoice,
    SelectField,
    SelectMultipleField,
    StringField,
    TextAreaField,
)
from wtforms.validators import DataRequired, InputRequired, Length, NumberRange, Optional
from wtforms.widgets import CheckboxInput, ListWidget

from app.services.studies.building import DEFAULT_CONSENT, DEFAULT_INSTRUCTIONS, SUPERPIXEL_OPTIONS
from egonet.clicks import SUPERPIXEL_DEFAULTS
from egonet.io import decode_json


class Form(FlaskForm):
    class Meta(FlaskForm.Meta):
        def wrap_formdata(self, form, formdata):
            if formdata is not _Auto:  # given explicitly by the caller
                return formdata
            if request.method not in ("POST", "PUT", "PATCH", "DELETE"):
                return None
            if request.files:
                return CombinedMultiDict((request.files, request.form))
            return request.form or ImmutableMultiDict()


# --------------------------------------------------------------------------
# Studies (the builder, its participants; a participant's code)

class StudyForm(Form):
    """The study builder: every key of a study's definition file (``app.services.studies.definition``).

    Field names are the definition's keys, ``.`` written ``_`` (``display_width_px``);
    lists and objects (catch trials, questions, conditions, quotas) are JSON.
    """

    version = HiddenField()
    name = StringField("Name", validators=[DataRequired(), Length(max=200)])
    activities = SelectMultipleField(
        "Activities",
        coerce=int,
        widget=ListWidget(prefix_label=False),
        option_widget=CheckboxInput(),
        validators=[DataRequired(message="Choose at least one activity.")],
    )
    frames_per_activity = IntegerField("Frames per activity", default=100, validators=[InputRequired(), NumberRange(1, 100_000)])
    seed = IntegerField("Seed", validators=[InputRequired(), NumberRange(0, 2**31 - 1)])
    time_limit_minutes = FloatField("Session time limit (minutes)", default=60, validators=[InputRequired(), NumberRange(0.05, 7 * 24 * 60)])
    trial_limit_seconds = IntegerField("Per-trial limit (seconds, empty for none)", validators=[Optional(), NumberRange(1, 24 * 3600)])
    multiple_clicks = BooleanField("Several clicks per frame (then Next; otherwise one click answers)", default=True)
    activity_order = SelectField(
        "Order of the photos",
        choices=[SelectChoice("shuffled", "each participant's own random order"),
                 SelectChoice("counterbalanced", "blocks of one activity, block order counterbalanced")],
        default="shuffled",
    )  # fmt: skip
    sigma_px = FloatField("Click width sigma (native px; empty: 60 px at 1280 wide, scaled)", validators=[Optional(), NumberRange(0.5, 10_000)])
    superpixel_method = SelectField("Superpixels", choices=[SelectChoice("hierarchical", "Hierarchical (boundaries, like MCG)"),
                                                             SelectChoice("slic", "SLIC"), SelectChoice("felzenszwalb", "Felzenszwalb")],
                                    default=SUPERPIXEL_DEFAULTS.method)
    fine_regions = IntegerField("Hierarchy: fine regions", default=SUPERPIXEL_DEFAULTS.fine_regions, validators=[Optional()])
    level = FloatField("Hierarchy: merge level", default=SUPERPIXEL_DEFAULTS.level, validators=[Optional()])
    max_region_share = FloatField("Hierarchy: largest region (share of the frame)", default=SUPERPIXEL_DEFAULTS.max_region_share,
                                  validators=[Optional()])
    n_segments = IntegerField("SLIC regions", default=SUPERPIXEL_DEFAULTS.n_segments, validators=[Optional()])
    compactness = FloatField("SLIC compactness", default=SUPERPIXEL_DEFAULTS.compactness, validators=[Optional()])
    scale = FloatField("Felzenszwalb scale", default=SUPERPIXEL_DEFAULTS.scale, validators=[Optional()])
    min_size = IntegerField("Felzenszwalb minimum region size", default=SUPERPIXEL_DEFAULTS.min_size, validators=[Optional()])
    max_side = IntegerField("Working resolution: longest side (px, empty for native)", default=SUPERPIXEL_DEFAULTS.max_side,
                            validators=[Optional()])
    instructions = TextAreaField("Instructions", default=DEFAULT_INSTRUCTIONS, validators=[Length(max=20_000)])
    consent = TextAreaField("Consent", default=DEFAULT_CONSENT, validators=[Length(max=20_000)])
    practice_trials = StringField("Practice trials (a number to draw, or frame ids as [12, 15])", validators=[Length(max=2000)])
    catch_trials = TextAreaField("Attention checks (catch trials)", validators=[Length(max=20_000)],
                                 description='[{"frame": 42, "position": 10, "box": [x0, y0, x1, y1]}]; without a box, the frame\'s ground truth')
    comprehension = TextAreaField("Comprehension questions", validators=[Length(max=50_000)],
                                  description='[{"question": "...", "options": ["...", "..."], "answer": 0}], '
                                              'or {"questions": [...], "max_attempts": 3}')
    conditions = TextAreaField("Conditions (between subjects)", validators=[Length(max=50_000)],
                               description='[{"name": "fast", "trial_limit_seconds": 5}, {"name": "slow", "trial_limit_seconds": 20}]')
    open_link = BooleanField("Open link: anyone with the link may take part (Prolific, MTurk)")
    open_link_cap = IntegerField("Participant cap (empty for none)", validators=[Optional(), NumberRange(1, 100_000)])
    open_link_quotas = TextAreaField("Quotas per condition", validators=[Length(max=5000)], description='{"fast": 25, "slow": 25}')
    completion_code = StringField("Completion code", validators=[Length(max=64)])
    completion_redirect_url = StringField("Redirect at the end (may hold {code})", validators=[Length(max=2000)],
                                          description="https://app.prolific.com/submissions/complete?cc={code}")
    completion_failed_code = StringField("Code after failed checks or time-up", validators=[Length(max=64)])
    display_mode = SelectField("Frame size", choices=[SelectChoice("fit", "fitted to the window"),
                                                      SelectChoice("width_px", "fixed width in CSS pixels"),
                                                      SelectChoice("fraction", "fixed fraction of the window")], default="fit")
    display_width_px = IntegerField("Width (CSS px)", validators=[Optional()])
    display_fraction = FloatField("Fraction of the window", validators=[Optional()])
    display_fullscreen = BooleanField("Full screen during the photos")
    display_min_window_width = IntegerField("Minimum window width (CSS px)", validators=[Optional()])
    display_min_window_height = IntegerField("Minimum window height (CSS px)", validators=[Optional()])
    display_allow_phones = BooleanField("Phones may take part", default=True)

    JSON_FIELDS = ("catch_trials", "comprehension", "conditions", "open_link_quotas")
    REGIONS = ("fine_regions", "level", "max_region_share", "n_segments", "compactness", "scale", "min_size")

    def definition(self, activity_names: dict[int, str]) -> dict[str, Any] | None:
        """The form as a definition document; None (with the field's error set) when a JSON field does not parse."""
        parsed = {}
        for name in (*self.JSON_FIELDS, "practice_trials"):
            text = (getattr(self, name).data or "").strip()
            try:
                parsed[name] = decode_json(text) if text else None
            except ValueError as exc:
                getattr(self, name).errors = [*getattr(self, name).errors, f"not valid JSON: {exc}"]
                return None
        method = self.superpixel_method.data
        doc: dict[str, Any] = {
            "name": self.name.data,
            "activities": [activity_names[i] for i in self.activities.data if i in activity_names],
            "frames_per_activity": self.frames_per_activity.data,
            "seed": self.seed.data,
            "time_limit_minutes": self.time_limit_minutes.data,
            "trial_limit_seconds": self.trial_limit_seconds.data,
            "multiple_clicks": self.multiple_clicks.data,
            "sigma_px": self.sigma_px.data,
            "regions": {"method": method, **{k: getattr(self, k).data for k in self.REGIONS if k in _method_options(method)},
                        "max_side": self.max_side.data},
            "instructions": self.instructions.data or "",
            "consent": self.consent.data or "",
            "activity_order": self.activity_order.data,
            "practice_trials": parsed["practice_trials"],
            "catch_trials": parsed["catch_trials"],
            "comprehension": parsed["comprehension"],
            "conditions": parsed["conditions"],
        }  # fmt: skip
        if self.open_link.data:
            doc["open_link"] = {"cap": self.open_link_cap.data, "quotas": parsed["open_link_quotas"]}
        completion = {"code": self.completion_code.data, "redirect_url": self.completion_redirect_url.data,
                      "failed_code": self.completion_failed_code.data}  # fmt: skip
        doc["completion"] = {k: v.strip() for k, v in completion.items() if v and v.strip()} or None
        doc["display"] = self._display()
        return doc

    def _display(self) -> dict[str, Any]:
        display: dict[str, Any] = {}
        if self.display_mode.data == "width_px":
            display["width_px"] = self.display_width_px.data
        elif self.display_mode.data == "fraction":
            display["fraction"] = self.display_fraction.data
        if self.display_fullscreen.data:
            display["fullscreen"] = True
        if self.display_min_window_width.data or self.display_min_window_height.data:
            display["min_window"] = {"width": self.display_min_window_width.data, "height": self.display_min_window_height.data}
        if not self.display_allow_phones.data:
            display["allow_phones"] = False
        return display

    def fill(self, doc: dict[str, Any], activity_ids: dict[str, int]) -> None:
        """Set the fields from a definition document (the builder's edit page)."""
        plain = ("name", "frames_per_activity", "seed", "time_limit_minutes", "trial_limit_seconds", "multiple_clicks",
                 "sigma_px", "instructions", "consent", "activity_order")  # fmt: skip
        for key in plain:
            getattr(self, key).data = doc.get(key)
        self.activities.data = [activity_ids[n] for n in doc.get("activities", []) if n in activity_ids]
        regions = doc.get("regions", {})
        self.superpixel_method.data = regions.get("method")
        for key in (*self.REGIONS, "max_side"):
            getattr(self, key).data = regions.get(key)
        for key in ("practice_trials", "catch_trials", "comprehension", "conditions"):
            getattr(self, key).data = json.dumps(doc[key], indent=1) if doc.get(key) else ""
        link = doc.get("open_link")
        self.open_link.data = link is not None
        self.open_link_cap.data = (link or {}).get("cap")
        self.open_link_quotas.data = json.dumps(link["quotas"]) if link and link.get("quotas") else ""
        completion = doc.get("completion", {})
        self.completion_code.data = completion.get("code", "")
        self.completion_redirect_url.data = completion.get("redirect_url", "")
        self.completion_failed_code.data = completion.get("failed_code", "")
        display = doc.get("display", {})
        self.display_mode.data = "width_px" if "width_px" in display else "fraction" if "fraction" in display else "fit"
        self.display_width_px.data = display.get("width_px")
        self.display_fraction.data = display.get("fraction")
        self.display_fullscreen.data = bool(display.get("fullscreen"))
        self.display_min_window_width.data = display.get("min_window", {}).get("width")
        self.display_min_window_height.data = display.get("min_window", {}).get("height")
        self.display_allow_phones.data = display.get("allow_phones", True)

    def field_for(self, key: str | None):
        """The field that holds a definition key (``display.min_window.width``, ``conditions[1].name``), if any."""
        if not key:
            return None
        key = key.split("[")[0]
        if key.startswith("regions."):
            key = "superpixel_method" if key == "regions.method" else key.removeprefix("regions.")
        if key in ("completion.code", "completion.redirect_url", "completion.failed_code"):
            key = key.replace(".", "_")
        parts = key.split(".")
        while parts:
            field = getattr(self, "_".join(parts), None)
            if field is not None and hasattr(field, "errors"):
                return field
            parts.pop()
        return None


def _method_options(method: str) -> tuple[str, ...]:
    return SUPERPIXEL_OPTIONS.get(method, ())


class DefinitionFileForm(Form):
    definition = FileField("Definition file (JSON)", validators=[FileRequired(message="Choose a definition file.")])


class PointsFileForm(Form):
    points = FileField("Attention points (CSV: frame,x,y)", validators=[FileRequired(message="Choose a CSV file of points.")])
    sigma = FloatField("Sigma (px; empty: 60 px at 1280 px wide, scaled to each frame)", validators=[Optional(), NumberRange(0.5, 10_000)])


class ParticipantsForm(Form):
    count = IntegerField("How many", default=5, validators=[InputRequired(), NumberRange(1, 500)])
    entry = SelectField("Entry", choices=[SelectChoice("code", "access codes"), SelectChoice("link", "single-use links (and codes)")], default="code")
    pilot = BooleanField("Pilot (marked in exports, left out of scores and the cap)")


class CodeForm(Form):
    code = StringField("Access code", validators=[DataRequired(), Length(max=32)])
