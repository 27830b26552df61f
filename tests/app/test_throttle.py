"""Throttles that count the right thing: study entry slowed (never locked) per address whatever the URL says,
open-link admissions on a budget of their own, counts taken atomically under concurrent requests, and the
arithmetic of docs/security.md. (Addresses behind a proxy: tests/system/test_proxy.py.)"""

import threading
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from app import throttle
from app.extensions import db
from app.models.studies import EntryCount, EntryKind, Study
from app.services import studies
from tests.app.access.studies import build_study
from tests.app.conftest import PASSWORD

DOCS = Path(__file__).resolve().parents[2] / "docs"
T0 = datetime(2026, 1, 5, 9, 0, tzinfo=UTC)  # the start of a window of 15 minutes, and of one of 1 minute


class Clock:
    def __init__(self):
        self.now = T0

    def __call__(self) -> datetime:
        return self.now

    def wait(self, seconds: int) -> None:
        self.now += timedelta(seconds=seconds)


@pytest.fixture
def clock(app, monkeypatch):
    """The throttle's time, moved by hand (with ``app``, whose teardown empties the tables ``app_with`` apps filled)."""
    clock = Clock()
    monkeypatch.setattr(throttle, "utcnow", clock)
    return clock


def two_studies(app, tmp_path, open_link=None):
    """Studies A and B with one participant each (by code); A may have an open link. Returns ids, codes, A's token."""
    with app.app_context():
        a = db.session.get(Study, build_study(tmp_path / "a", frames=2, per_activity=1, participants=1, open_link=open_link)["study"])
        b = db.session.get(Study, build_study(tmp_path / "b", activities=("dining",), frames=1, per_activity=1, participants=1)["study"])
        return {"a": a.id, "b": b.id, "code_a": a.participants[0].code, "code_b": b.participants[0].code, "token": a.open_link_token}


def enter(app, code, study=None, address="127.0.0.1"):
    client = app.test_client()
    client.environ_base["REMOTE_ADDR"] = address
    return client.post("/s/" + (f"?study={study}" if study else ""), data={"code": code})


def test_a_lab_behind_one_address_is_slowed_down_never_locked_out(app_with, tmp_path, clock):
    """One student typing wrong codes (or a script) makes the lab's address wait seconds, not the window;
    and the open link, which takes no secret, never waits for wrong codes."""
    app = app_with(RATELIMIT_ENTRY_FAILURES=3, RATELIMIT_ENTRY_MAX_WAIT=8)
    ids = two_studies(app, tmp_path, open_link={})
    assert [enter(app, "ZZZZ-ZZZZ", ids["a"]).status_code for _ in range(4)] == [401] * 4  # 3 free, the 4th sets a wait
    waits = []
    for _ in range(40):  # the student keeps trying, as fast as the waits allow
        refused = enter(app, "ZZZZ-ZZZZ", ids["a"])
        assert refused.status_code == 429 and b"Try again in" in refused.data
        waits.append(int(refused.headers["Retry-After"]))
        clock.wait(waits[-1])
        assert enter(app, "ZZZZ-ZZZZ", ids["a"]).status_code == 401
    assert waits[:5] == [1, 2, 4, 8, 8] and max(waits) == 8  # growing, then capped: a classmate waits 8 s at most
    waiting = enter(app, ids["code_a"], ids["a"])
    assert waiting.status_code == 429 and waiting.headers["Retry-After"] == "8"
    clock.wait(8)
    assert enter(app, ids["code_a"], ids["a"]).headers["Location"].endswith("/s/consent")
    # Meanwhile a class arrives through the open link from the same address: wrong codes do not count there.
    assert {app.test_client().post(f"/s/o/{ids['token']}").status_code for _ in range(5)} == {302}


def test_wrong_codes_count_per_address_whatever_study_the_url_names(app_with, make_user, tmp_path, clock):
    """Review: after ?study=1 was locked, a right code of study 1 posted at ?study=2 signed in (200 x (studies + 1) tries)."""
    app = app_with(RATELIMIT_ENTRY_FAILURES=3, RATELIMIT_ENTRY_MAX_WAIT=30)
    ids = two_studies(app, tmp_path)
    assert [enter(app, "ZZZZ-ZZZZ", ids["a"]).status_code for _ in range(4)] == [401] * 4
    for study in (ids["a"], ids["b"], None):  # the study named, another one, none: the same count
        assert enter(app, ids["code_a"], study).status_code == 429
    assert [enter(app, "ZZZZ-ZZZZ", ids["b"], address="192.0.2.7").status_code for _ in range(3)] == [401] * 3  # its own count
    assert enter(app, ids["code_b"], ids["b"], address="198.51.100.1").headers["Location"].endswith("/s/consent")
    guesser = app.test_client()
    guesser.environ_base["REMOTE_ADDR"] = "192.0.2.7"
    assert [guesser.get(f"/s/l/guess{i}").status_code for i in range(2)] == [404, 429]  # unknown links count too
    with app.app_context():
        rows = db.session.execute(db.select(EntryCount).order_by(EntryCount.id)).scalars().all()
        assert [(r.scope, r.address, r.count) for r in rows] == [("codes", "127.0.0.1", 4), ("codes", "192.0.2.7", 4),
                                                                ("codes", "198.51.100.1", 0)]  # a success is given back

    # Staff see every address's count on a study's page and clear one.
    make_user("admin", "admin")
    staff = app.test_client()
    assert staff.login("admin", PASSWORD).status_code == 302
    page = staff.get(f"/studies/{ids['b']}").get_data(as_text=True)
    assert 'data-address="127.0.0.1"' in page and 'data-address="192.0.2.7"' in page and "codes and links" in page
    assert staff.post(f"/studies/{ids['b']}/entry-locks/{rows[0].id}/clear").status_code == 302
    assert enter(app, ids["code_a"]).headers["Location"].endswith("/s/consent")


def test_the_docs_arithmetic_is_what_the_code_does(app_with, tmp_path, clock):
    """docs/security.md's numbers follow from the default config; a simulated guesser gets exactly ``most_guesses``."""
    app = app_with()
    config = app.config
    with app.app_context():
        window = throttle.window_s()
    free, max_wait = config["RATELIMIT_ENTRY_FAILURES"], config["RATELIMIT_ENTRY_MAX_WAIT"]
    most = throttle.most_guesses(free, max_wait, window)
    per_year = most * (365 * 24 * 3600 // window)
    years = 31**8 / (1000 * per_year)  # one of a 1,000-participant study's codes
    text = " ".join((DOCS / "security.md").read_text().split())
    assert (free, max_wait, window, most) == (200, 30, 900, 234)
    for phrase in (f"the first {free}", f"at most {max_wait} s", f"at most {most} guesses per address in each 15-minute window",
                   f"about once in {round(years, -1):.0f} years", f"{config['RATELIMIT_OPEN_ADMISSIONS']} newcomers"):
        assert phrase in text, phrase

    # The code gives a guesser who waits exactly as told exactly that many checks per window (small numbers: 1 minute).
    small = app_with(RATELIMIT_ENTRY_FAILURES=5, RATELIMIT_ENTRY_MAX_WAIT=8, RATELIMIT_WINDOW="1 minute")
    checked = 0
    while clock.now < T0 + timedelta(minutes=1):
        response = enter(small, "ZZZZ-ZZZZ")
        if response.status_code == 401:
            checked += 1
        else:
            clock.wait(int(response.headers["Retry-After"]))
    assert checked == throttle.most_guesses(5, 8, 60) == 15  # 6 at 0 s, then at 1, 3, 7 s and every 8 s: 15, ..., 55


def test_open_link_admissions_have_a_budget_per_address_and_study(app_with, tmp_path, clock):
    """Review: one client filled a 100-place study in 5.4 s with made-up ids. Now: a budget per address and study."""
    app = app_with(RATELIMIT_OPEN_ADMISSIONS=3, RATELIMIT_ENTRY_MAX_WAIT=30)
    ids = two_studies(app, tmp_path, open_link={})
    token = ids["token"]
    admitted = [app.test_client().post(f"/s/o/{token}", data={"PROLIFIC_PID": f"{i:024x}"}).status_code for i in range(6)]
    assert admitted == [302, 302, 302, 302, 429, 429]
    assert app.test_client().post(f"/s/o/{token}", data={"PROLIFIC_PID": f"{9:024x}"}).headers["Retry-After"] == "1"
    elsewhere = app.test_client()
    elsewhere.environ_base["REMOTE_ADDR"] = "192.0.2.7"
    assert elsewhere.post(f"/s/o/{token}").status_code == 302
    # Codes from the same address are not slowed by admissions.
    assert enter(app, ids["code_a"]).headers["Location"].endswith("/s/consent")
    clock.wait(1)
    assert app.test_client().post(f"/s/o/{token}").status_code == 302
    # Refusals are not admissions: a paused study gives them back.
    clock.wait(3600)
    with app.app_context():
        studies.set_status(db.session.get(Study, ids["a"]), "paused")
    assert {app.test_client().post(f"/s/o/{token}").status_code for _ in range(5)} == {409}
    with app.app_context():
        (row,) = db.session.execute(db.select(EntryCount).filter_by(scope=f"open-{ids['a']}", window=int(clock.now.timestamp()) // 900)).scalars()
        assert row.count == 0


def test_a_class_of_100_behind_one_address_fits_the_default_budget(app, tmp_path):
    with app.app_context():
        study = db.session.get(Study, build_study(tmp_path, frames=1, per_activity=1, participants=0, open_link={})["study"])
        token = study.open_link_token
    assert app.config["RATELIMIT_OPEN_ADMISSIONS"] >= 100
    assert {app.test_client().post(f"/s/o/{token}").status_code for _ in range(100)} == {302}


def _at_once(count: int, call) -> list:
    barrier, results = threading.Barrier(count), []

    def run():
        barrier.wait()
        results.append(call())

    threads = [threading.Thread(target=run) for _ in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=120)
    return results


def test_concurrent_wrong_codes_are_counted_exactly(app_with, tmp_path, clock):
    """Review: 16 simultaneous first failures made 5 rows. Now one row per (scope, address, window), every failure in it,
    and past the budget only one attempt at a time is checked."""
    app = app_with(RATELIMIT_ENTRY_FAILURES=20, RATELIMIT_ENTRY_MAX_WAIT=30)
    two_studies(app, tmp_path)
    first = _at_once(16, lambda: enter(app, "ZZZZ-ZZZZ").status_code)
    assert first == [401] * 16
    with app.app_context():
        assert [(r.scope, r.count) for r in db.session.execute(db.select(EntryCount)).scalars()] == [("codes", 16)]
    statuses = [s for _ in range(5) for s in _at_once(16, lambda: enter(app, "ZZZZ-ZZZZ").status_code)]
    assert statuses.count(401) == 20 + 1 - 16 and statuses.count(429) == 80 - 5  # 20 free, the 21st checked, then waits


def test_concurrent_wrong_passwords_are_counted_exactly(app_with, make_user):
    """Review: 96 wrong passwords from 16 threads had 30 checked instead of 20."""
    app = app_with(RATELIMIT_FAILURES=20, RATELIMIT_WINDOW="1 hour")
    make_user("admin", "admin")
    statuses = [s for _ in range(6) for s in _at_once(16, lambda: app.test_client().login("admin", "wrong password").status_code)]
    assert statuses.count(401) == 20 and statuses.count(429) == 76


def test_a_form_error_is_not_a_guess_and_a_success_clears_the_count(app_with, make_user):
    app = app_with(RATELIMIT_FAILURES=3, RATELIMIT_WINDOW="1 hour")
    make_user("annotator", "ana")
    client = app.test_client()
    assert [client.post("/login", data={"username": "ana"}).status_code for _ in range(5)] == [400] * 5  # no password sent
    assert [client.login("ana", "wrong password").status_code for _ in range(2)] == [401, 401]
    assert client.login("ana", PASSWORD).status_code == 302
    assert client.post("/logout").status_code == 302
    assert [client.login("ana", "wrong password").status_code for _ in range(4)] == [401, 401, 401, 429]


def test_a_known_single_use_link_is_never_counted(app_with, tmp_path, clock):
    """Unknown links count with wrong codes; opening a known one (its Start page) is no guess."""
    app = app_with(RATELIMIT_ENTRY_FAILURES=2)
    with app.app_context():
        study = db.session.get(Study, build_study(tmp_path, frames=1, per_activity=1, participants=0)["study"])
        (person,) = studies.add_participants(study, count=1, entry=EntryKind.LINK)
        token = person.link_token
    assert [app.test_client().get(f"/s/l/{token}").status_code for _ in range(5)] == [200] * 5
    with app.app_context():
        assert all(row.count == 0 for row in db.session.execute(db.select(EntryCount)).scalars())


@pytest.mark.parametrize("value", ["1", -1, 11, True, 1.0])
def test_trusted_proxies_must_be_a_small_whole_number(app_with, value):
    with pytest.raises(RuntimeError, match="TRUSTED_PROXIES must be a whole number from 0 to 10"):
        app_with(TRUSTED_PROXIES=value)


def test_one_trusted_proxy_gives_the_address_it_saw(app_with, make_user):
    """The proxy's own (last) X-Forwarded-For entry is the client; what the client wrote before it is ignored."""
    app = app_with(TRUSTED_PROXIES=1, RATELIMIT_FAILURES=2, RATELIMIT_WINDOW="1 hour")
    make_user("admin", "admin")

    def log_in(chain: str, password: str = "wrong password") -> int:
        client = app.test_client()
        client.environ_base["HTTP_X_FORWARDED_FOR"] = chain
        return client.login("admin", password).status_code

    assert [log_in(f"192.0.2.{i}, 203.0.113.5") for i in range(3)] == [401, 401, 429]
    assert log_in("203.0.113.5, 198.51.100.7", PASSWORD) == 302
