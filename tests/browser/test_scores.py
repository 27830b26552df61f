"""The Scores page in real Chromium: a trained run, the baselines and two people in the table, the plots, a download."""

from pathlib import Path

import numpy as np
import pytest
import torch

from app.extensions import db
from app.models import Activity
from app.services import ground_truth, studies, training
from app.services.demo import create_demo
from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser


def answer_at_the_object(participant) -> None:
    """Consent, start and click the centre of each frame's ground-truth object (or answer none)."""
    studies.answer_consent(participant, agree=True)
    studies.start_session(participant)
    state = studies.session_state(participant)
    while state.trial is not None:
        frame = state.trial.frame
        mask = ground_truth.mask_of(ground_truth.ground_truths([frame.id])[frame.id])
        rows, cols = np.nonzero(mask)
        if rows.size:
            # P02 aims a little off: the two people differ.
            shift = 6.0 * (participant.number - 1)
            answer = studies.Answer(clicks=[(float(cols.mean()) + shift, float(rows.mean()), 700.0)])
        else:
            answer = studies.Answer(clicks=[], none=True)
        state = studies.submit(participant, state.trial, answer)


def test_scores_page_shows_the_table_and_the_plots(live_app, live_server, page, tmp_path):
    live_app.config["CHECKPOINT_ROOT"] = str(tmp_path / "checkpoints")
    with live_app.app_context():
        create_demo(frames_per_activity=3, unlabelled_fraction=0, seed=1, width=160, height=120)
        chosen = db.session.execute(db.select(Activity.id).where(Activity.name.in_(["cooking", "hotel"]))).scalars().all()
        study = studies.create_study(name="browser study", activity_ids=chosen, frames_per_activity=2, seed=3, sigma_px=15.0)
        for person in studies.add_participants(study, count=2):
            answer_at_the_object(person)
        # A tiny model trained for one epoch: one row, scored on its held-out frames (the last of each activity).
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            request = training.RunRequest(model="egonet-lite", folds="single", epochs=1, width=64, height=48, batch_size=2, device="cpu")
            run_id = training.execute_run(training.create_run(request).id).id
        finally:
            torch.set_num_threads(threads)

    sign_in(page, live_app, live_server)
    page.get_by_role("link", name="Scores").click()
    page.wait_for_load_state("networkidle")
    table = page.locator("#score-table")
    names = [n.strip() for n in table.locator("tbody th.method").all_inner_texts()]
    assert names == [f"egonet-lite (run {run_id})", "AOP", "centre prior", "saliency", "GBVS",
                     "handled + viewed object (hands: labelled tactile objects)", "P01", "P02"]
    header = table.locator("thead tr").first.inner_text().lower()
    for activity in ("cooking", "hotel", "shopping", "mean"):
        assert activity in header
    # People: MF only.
    p01 = table.locator('tr[data-row^="participant:"]').first.locator("td")
    assert p01.nth(0).inner_text().startswith("0.") and p01.nth(1).inner_text() == "–"
    assert table.locator("td.best").count() >= 8

    plots = page.locator(".pr-plot")
    assert plots.count() == 8  # all activities pooled, then the seven activities
    first = plots.first.locator("svg")
    assert first.is_visible()
    assert first.bounding_box()["width"] > 200
    assert first.locator("polyline.curve").count() == 8
    assert plots.nth(1).locator("polyline.curve").count() == 8  # cooking: the model, the five baselines and both people
    assert plots.nth(3).locator("polyline.curve").count() == 6  # dishwashing: no study frames there
    screenshot(page, "scores-page")

    # Only the study: untick the run and the baselines and score again.
    page.uncheck(f"input[name=runs][value='{run_id}']")
    page.uncheck("input[name=baselines]")
    page.click("#score-choice button[type=submit]")
    page.wait_for_load_state("networkidle")
    assert [n.strip() for n in page.locator("#score-table tbody th.method").all_inner_texts()] == ["P01", "P02"]
    assert page.locator(".pr-plot").count() == 3  # pooled, cooking, hotel
    screenshot(page, "scores-people")

    with page.expect_download() as info:
        page.click("text=CSV")
    lines = Path(info.value.path()).read_text().splitlines()
    assert lines[0].startswith("method,kind,cooking MF") and [line.split(",")[0] for line in lines[1:]] == ["P01", "P02"]
