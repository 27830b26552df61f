"""Many users at once on the production server: no errors, nothing lost.

A short run of the load simulation (``tests/system/loadgen.py``; the
latency figures come from ``bench/load.py``): annotators browse, run GrabCut
boxes and strokes and save masks while participants answer trials, against
gunicorn with several processes on PostgreSQL. Every request must succeed
and every acknowledged save must be in the database afterwards.

The simulated users think a quarter of a person's time (``pace``): each
annotator's cycle (a box, three strokes, a save) has at most 6 s of thinking
instead of 24, so the same requests come four times as close together, and
each run lasts a few seconds past the last arrival's first cycle.
"""

import os

import pytest

from tests.system.loadgen import ABUSE_BOX, ABUSE_STROKE, BOX, STROKE, run_load

POSTGRES_URL = os.environ.get("EGONET_TEST_POSTGRES_URL")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not POSTGRES_URL, reason="the load test runs on PostgreSQL (EGONET_TEST_POSTGRES_URL)"),
]


def test_twenty_users_no_errors_nothing_lost(tmp_path):
    annotators = 14
    result = run_load(POSTGRES_URL, tmp_path, users=20, participants=6, duration=8, ramp=5,
                      workers=2, threads=4, size=(320, 240), pace=0.25)
    stats = result.stats
    assert sum(stats.errors.values()) == 0, stats.error_samples[:10]
    assert result.lost == 0
    # Every annotator finishes at least the cycle it started: a box, three strokes, a save.
    assert result.saves >= annotators
    assert len(stats.times[STROKE]) == 3 * len(stats.times[BOX]) >= 3 * annotators
    assert len(stats.times["POST /s/api/trials/<id>"]) >= 6


def test_an_abusive_annotator_costs_the_others_no_request(tmp_path):
    """One annotator sending the largest GrabCut calls allowed, back to back:
    those calls are accepted (the limits and the simulation agree), and
    nobody else's request fails or save goes missing. The abuser goes on
    for 10 s: everyone else arrives within 3 s and thinks at most 6 s a
    cycle, so each one's first cycle runs while the abuser is at work."""
    result = run_load(POSTGRES_URL, tmp_path, users=10, participants=3, duration=10, ramp=3,
                      workers=2, threads=4, size=(320, 240), abuse=True, pace=0.25)
    stats = result.stats
    assert sum(stats.errors.values()) == 0, stats.error_samples[:10]
    assert result.lost == 0
    assert stats.times[ABUSE_BOX] and stats.times[ABUSE_STROKE]
    assert result.saves >= 7 and len(stats.times["POST /s/api/trials/<id>"]) >= 3
