"""A human study in real Chromium: the admin builds it, a participant takes it, the admin sees the masks."""

import numpy as np
import pytest

from app.extensions import db
from app.models import Activity
from app.models.studies import EndReason, EventKind, Outcome, Participant, Study
from app.services import ground_truth, studies
from app.services.demo import create_demo
from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser

LOADED = "img => img.complete && img.naturalWidth > 0"


def wait_for_trial(page, position: int) -> None:
    """Wait until trial ``position`` is painted (the page marks it once its frame is on screen)."""
    page.wait_for_selector(f'#trial-app[data-painted="{position}"]')


def click_frame(page, u: float, v: float) -> None:
    """Click at fractions (u, v) of the drawn frame."""
    box = page.locator("#stage img.frame").bounding_box()
    page.mouse.click(box["x"] + u * box["width"], box["y"] + v * box["height"])


def test_participant_session_with_reload_and_admin_results(live_app, live_server, page, browser):
    with live_app.app_context():
        create_demo(frames_per_activity=3, unlabelled_fraction=0, seed=1, width=320, height=240)
        activity_ids = {a.name: a.id for a in db.session.execute(db.select(Activity)).scalars()}

    # The admin builds a study: 2 frames from each of 2 activities, a short time limit, links.
    sign_in(page, live_app, live_server)
    page.goto(live_server + "/studies/new")
    assert "3 eligible" in page.inner_text(".activity-choices")
    page.fill("input[name=name]", "browser study")
    page.check(f"input[name=activities][value='{activity_ids['cooking']}']")
    page.check(f"input[name=activities][value='{activity_ids['hotel']}']")
    page.fill("input[name=frames_per_activity]", "2")
    page.fill("input[name=time_limit_minutes]", "3")
    screenshot(page, "study-admin-new")
    page.click(".study-form button[type=submit]")
    page.wait_for_load_state("networkidle")
    assert "4 frames drawn" in page.inner_text(".flash")
    page.fill("input[name=count]", "2")
    page.select_option("select[name=entry]", "link")
    page.click("text=Add participants")
    page.wait_for_load_state("networkidle")
    links = [page.locator("input.link").nth(i).input_value() for i in range(2)]
    assert all("/s/l/" in link for link in links)
    page.locator("input.link").first.focus()  # selected, ready to copy
    assert page.locator("input.link").first.evaluate("el => el.selectionStart === 0 && el.selectionEnd === el.value.length")
    screenshot(page, "study-admin-detail")

    # The participant, in their own browser context, opens the link: a Start button (a link
    # preview that fetches the link does not use it up), which signs them in.
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    person = context.new_page()
    refused = []

    def on_response(response) -> None:
        if response.status >= 400:
            refused.append(f"{response.status} {response.url}")

    person.on("response", on_response)  # e.g. a frame the page may not fetch (only the current and the next)
    person.goto(links[0])
    screenshot(person, "study-link")
    person.click("#start-link")
    assert person.url.endswith("/s/consent")
    screenshot(person, "study-consent")
    person.click("#agree")
    assert person.url.endswith("/s/instructions")
    assert "Backspace" in person.inner_text("table.keys")
    assert person.locator(".prose p").count() == 3  # the default text's paragraphs, sent back by the form
    screenshot(person, "study-instructions")
    person.click("#start")
    wait_for_trial(person, 1)
    assert person.inner_text("#progress-text") == "Photo 1 of 4"
    assert person.locator("#stage img.frame").evaluate(LOADED)

    # Trial 1: two clicks, undo one, click again, Enter.
    click_frame(person, 0.5, 0.5)
    click_frame(person, 0.1, 0.1)
    person.keyboard.press("Backspace")
    click_frame(person, 0.75, 0.25)
    assert person.locator(".marker").count() == 2
    screenshot(person, "study-trial-clicks")
    person.keyboard.press("Enter")
    wait_for_trial(person, 2)
    assert person.locator(".marker").count() == 0
    assert person.locator("#progress-bar").evaluate("bar => [bar.value, bar.max]") == [1, 4]

    # Trial 2: a click, then a reload: the page resumes at trial 2, without the unsent click.
    click_frame(person, 0.3, 0.6)
    person.reload()
    wait_for_trial(person, 2)
    assert person.inner_text("#progress-text") == "Photo 2 of 4" and person.locator(".marker").count() == 0
    screenshot(person, "study-after-reload")
    person.keyboard.press("n")
    wait_for_trial(person, 3)

    # Trial 3: the Next button; trial 4: Enter. The window is resized on the way.
    click_frame(person, 0.2, 0.8)
    person.set_viewport_size({"width": 900, "height": 700})
    person.wait_for_timeout(400)
    person.click("#next")
    wait_for_trial(person, 4)
    click_frame(person, 0.9, 0.9)
    person.keyboard.press("Enter")
    person.wait_for_url("**/s/done")
    assert "You answered all 4 photos" in person.inner_text("#thanks")
    screenshot(person, "study-done")
    # Back does not bring the last trial back with its clock running: the page is not stored.
    person.go_back()
    person.wait_for_url("**/s/done")
    assert "You answered all 4 photos" in person.inner_text("#thanks")
    assert refused == []

    with live_app.app_context():
        study = db.session.execute(db.select(Study).filter_by(name="browser study")).scalar_one()
        participant = study.participants[0]
        assert participant.end_reason is EndReason.COMPLETED and participant.link_used_at is not None
        trials = participant.trials
        assert [t.outcome for t in trials] == [Outcome.CLICKED, Outcome.NONE, Outcome.CLICKED, Outcome.CLICKED]
        first = trials[0]
        w, h = first.frame.width, first.frame.height
        (x0, y0), (x1, y1) = [(c.x, c.y) for c in first.clicks]
        assert abs(x0 - (0.5 * w - 0.5)) <= 0.5 and abs(y0 - (0.5 * h - 0.5)) <= 0.5  # native pixels
        assert abs(x1 - (0.75 * w - 0.5)) <= 0.5 and abs(y1 - (0.25 * h - 0.5)) <= 0.5
        assert 0 < first.clicks[0].rt_ms < first.clicks[1].rt_ms <= first.rt_ms
        assert first.window_width == 1280 and first.display_height > 0
        assert [e.kind for e in first.events] == [EventKind.UNDO]
        assert EventKind.RELOAD in [e.kind for e in trials[1].events] and trials[1].clicks == []
        assert EventKind.RESIZE in [e.kind for e in trials[2].events] and trials[2].window_width == 900
        study_id, participant_id = study.id, participant.id
        first_frame = first.study_frame_id
    context.close()

    # The admin sees progress, the participant's soft masks and the mean maps.
    page.goto(f"{live_server}/studies/{study_id}")
    assert "completed" in page.inner_text("#participants") and "4 / 4" in page.inner_text("#participants")
    page.goto(f"{live_server}/studies/{study_id}/participants/{participant_id}")
    page.wait_for_load_state("networkidle")
    overlays = page.locator(".trial-tile img")
    assert overlays.count() == 4
    for i in range(4):
        overlays.nth(i).scroll_into_view_if_needed()
        page.wait_for_function("img => img.complete && img.naturalWidth > 0", arg=overlays.nth(i).element_handle())
    screenshot(page, "study-admin-participant")
    page.goto(f"{live_server}/studies/{study_id}/frames")
    page.wait_for_load_state("networkidle")
    assert page.locator(".trial-grid img").count() == 4
    screenshot(page, "study-admin-mean-maps")
    page.goto(f"{live_server}/studies/{study_id}/frames/{first_frame}")
    page.wait_for_load_state("networkidle")
    assert page.locator("#mean-map").evaluate(LOADED)
    screenshot(page, "study-admin-frame")


def test_time_runs_out_on_screen(live_app, live_server, page):
    with live_app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, seed=2, width=320, height=240)
        cooking = db.session.execute(db.select(Activity).filter_by(name="cooking")).scalar_one()
        study = studies.create_study(name="short", activity_ids=[cooking.id], frames_per_activity=2, time_limit_s=4)
        code = studies.format_code(studies.add_participants(study, count=1)[0].code)

    page.goto(live_server + "/s/")
    screenshot(page, "study-entry")
    page.fill("input[name=code]", code.lower())  # as typed
    page.click("main button[type=submit]")
    page.click("#agree")
    page.click("#start")
    wait_for_trial(page, 1)
    click_frame(page, 0.4, 0.4)  # a click, but no Next before the time is up
    assert page.inner_text("#time-left") in ("0:04", "0:03")
    screenshot(page, "study-time-running")
    page.wait_for_url("**/s/done", timeout=15_000)
    assert "The time is up. You answered 1 of 2" in page.inner_text("#thanks")
    screenshot(page, "study-time-up")
    with live_app.app_context():
        participant = db.session.execute(db.select(Participant)).scalar_one()
        assert participant.end_reason is EndReason.TIME_UP
        first, second = participant.trials
        assert first.outcome is Outcome.TIMED_OUT and len(first.clicks) == 1
        assert second.outcome in (None, Outcome.EXPIRED)


# --------------------------------------------------------------------------
# Online: a whole Prolific-style session, on a desktop and on a phone

PROLIFIC_DONE = "https://app.prolific.com/submissions/complete"
IPHONE = "Mozilla/5.0 (iPhone; CPU iPhone OS 17_4 like Mac OS X) AppleWebKit/605.1.15 (KHTML, like Gecko) Version/17.4 Mobile/15E148 Safari/604.1"
DEVICES = {
    "desktop": {"viewport": {"width": 1280, "height": 800}},
    "phone": {"viewport": {"width": 390, "height": 844}, "device_scale_factor": 3, "is_mobile": True, "has_touch": True, "user_agent": IPHONE},
}


def online_study(live_app) -> dict:
    """Cooking and hotel frames (2 each), a practice frame, a catch trial on a dining frame's action-object, one question."""
    create_demo(frames_per_activity=2, unlabelled_fraction=0, seed=3, width=320, height=240)
    by_name = {a.name: a for a in db.session.execute(db.select(Activity)).scalars()}
    dining = [f for f in ground_truth.labelled_frames([by_name["dining"].id])]
    study = studies.create_study(
        name="online", activity_ids=[by_name["cooking"].id, by_name["hotel"].id], frames_per_activity=2, seed=4,
        multiple_clicks=False, practice_trials=[dining[0].id], catch_trials=[{"frame": dining[1].id, "position": 3}],
        comprehension=[{"question": "What do you click?", "options": ["The brightest spot", "The centre of the object the person acts on"],
                        "answer": 1}],
        open_link={"cap": 10}, completion={"code": "CC7W9X", "redirect_url": PROLIFIC_DONE + "?cc={code}"},
        display={"width_px": 360, "min_window": {"width": 360, "height": 480}, "fullscreen": True},
    )  # fmt: skip
    mask = ground_truth.mask_of(ground_truth.ground_truths([dining[1].id])[dining[1].id])
    rows, cols = np.nonzero(mask)
    centre = np.argmin((rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2)  # the object's pixel nearest its centroid
    return {"id": study.id, "link": f"/s/o/{study.open_link_token}", "catch_frame": dining[1].id,
            "catch_at": ((cols[centre] + 0.5) / 320, (rows[centre] + 0.5) / 240)}  # fmt: skip


def tap_frame(page, u: float, v: float, *, touch: bool) -> None:
    box = page.locator("#stage img.frame").bounding_box()
    x, y = box["x"] + u * box["width"], box["y"] + v * box["height"]
    page.touchscreen.tap(x, y) if touch else page.mouse.click(x, y)


def walk(browser, live_server, made: dict, device: str) -> str:
    """Arrive from Prolific, answer the question (wrong, then right), practise, do the trials, get sent back with the code."""
    context = browser.new_context(**DEVICES[device])
    context.route(PROLIFIC_DONE + "*", lambda route: route.fulfill(status=200, content_type="text/html", body="<p>Prolific</p>"))
    page = context.new_page()
    touch = device == "phone"
    pid = f"60c0ffee{device.encode().hex()}00000000"[:24]  # a Prolific id: 24 hexadecimal digits
    overflow = "() => document.documentElement.scrollWidth <= innerWidth"
    page.goto(f"{live_server}{made['link']}?PROLIFIC_PID={pid}&STUDY_ID=st123&SESSION_ID=se456")
    assert page.locator("a.brand").count() == 0 and page.locator("a[href='/']").count() == 0  # no staff links
    screenshot(page, f"online-{device}-arrive")
    page.click("#start-open")
    page.click("#agree")
    assert page.evaluate(overflow), "the instructions overflow the window"
    page.check("input[name=q0][value='0']")
    page.click("#check-answers")
    assert "Some answers are not right" in page.inner_text("#quiz-wrong")
    screenshot(page, f"online-{device}-question-wrong")
    page.check("input[name=q0][value='1']")
    page.click("#check-answers")
    page.wait_for_url("**/s/practice")
    wait_for_trial(page, 1)
    assert page.inner_text("#progress-text") == "Practice 1 of 1" and not page.is_visible("#session-clock")
    assert page.locator("#stage img.frame").bounding_box()["width"] == pytest.approx(360, abs=0.5)  # the fixed size, phone or not
    assert page.evaluate(overflow), "the practice page overflows the window"
    screenshot(page, f"online-{device}-practice")
    tap_frame(page, 0.5, 0.5, touch=touch)
    page.wait_for_url("**/s/ready")
    page.click("#start")
    for position in range(1, 6):
        wait_for_trial(page, position + 1)
        if position == 1:  # the study asks for full screen: the photos are covered until it is on
            assert page.is_visible("#blocker") and "full screen" in page.inner_text("#blocker-text")
            screenshot(page, f"online-{device}-fullscreen")
            page.click("#fullscreen")
            page.wait_for_function("() => document.fullscreenElement !== null && document.getElementById('blocker').hidden")
        if position == 2 and not touch:  # too small a window is covered too, and the clicks wait
            page.set_viewport_size({"width": 340, "height": 700})
            page.wait_for_function("() => !document.getElementById('blocker').hidden")
            assert "at least 360 × 480 pixels; yours is 340 × 700" in page.inner_text("#blocker-text")
            screenshot(page, f"online-{device}-too-small")
            page.set_viewport_size(DEVICES[device]["viewport"])
            page.wait_for_function("() => document.getElementById('blocker').hidden")
        assert page.inner_text("#progress-text") == f"Photo {position} of 5"
        if position == 1:
            screenshot(page, f"online-{device}-trial")
        u, v = made["catch_at"] if position == 3 else (0.3, 0.6)
        tap_frame(page, u, v, touch=touch)
    page.wait_for_url("**/s/done")
    assert page.inner_text("#completion-code") == "CC7W9X"
    screenshot(page, f"online-{device}-done")
    if touch:
        page.click("#redirect")
    page.wait_for_url(PROLIFIC_DONE + "?cc=CC7W9X", timeout=10_000)  # on the desktop, by itself after 3 s
    context.close()
    return pid


def test_a_prolific_session_on_a_desktop_and_a_phone(live_app, live_server, browser):
    with live_app.app_context():
        made = online_study(live_app)
    pids = [walk(browser, live_server, made, device) for device in ("desktop", "phone")]
    with live_app.app_context():
        study = db.session.get(Study, made["id"])
        desktop, phone = study.participants
        assert [(p.platform, p.external_id, p.external) for p in (desktop, phone)] == [
            ("prolific", pid, {"STUDY_ID": "st123", "SESSION_ID": "se456"}) for pid in pids]  # fmt: skip
        for person, width in ((desktop, 1280), (phone, 390)):
            assert person.end_reason is EndReason.COMPLETED and person.completion_code == "CC7W9X"
            assert person.comprehension_attempts == 2 and person.environment["window"]["width"] == width
            assert person.environment["time_zone"] and person.environment["screen"]["width"] > 0
            assert [t.kind.value for t in person.trials] == ["practice", "main", "main", "catch", "main", "main"]
            catch = person.trials[3]
            assert catch.study_frame.frame_id == made["catch_frame"] and catch.hit is True
            assert all(t.display_width == pytest.approx(360, abs=0.5) and t.window_width == width for t in person.trials)
            kinds = [e.kind for t in person.trials for e in t.events]
            assert EventKind.FULLSCREEN in kinds and (EventKind.RESIZE in kinds) == (person is desktop)
            assert studies.checks_of([person])[person.id].passed is True
        assert phone.environment["touch"] is True and phone.environment["pixel_ratio"] == 3 and "iPhone" in phone.user_agent
        assert desktop.environment["touch"] is False
