"""A running run holds a lease; once it expires (its worker died) exactly one worker queues the run again."""

import threading
from datetime import timedelta

from sqlalchemy import update

from app.extensions import db
from app.models import utcnow
from app.models.training import FoldsMode, RunStatus, TrainingRun
from app.services import training


def running(age_s: float, folds: FoldsMode = FoldsMode.LOAO) -> int:
    """A running run whose lease was last renewed ``age_s`` seconds ago."""
    run = TrainingRun(name=f"{age_s}s", model_name="egonet-lite", folds=folds, epochs=2, device="cpu", seed=0,
                      config={"train": {}}, status=RunStatus.RUNNING, started_at=utcnow())
    db.session.add(run)
    db.session.commit()
    db.session.execute(update(TrainingRun).where(TrainingRun.id == run.id)
                       .values(updated_at=utcnow() - timedelta(seconds=age_s)))
    db.session.commit()
    return run.id


def test_an_expired_lease_is_taken_over_exactly_once_by_two_workers_and_a_live_one_never(
        app, app_with, database_url, storage_url, tmp_path, admin_client, monkeypatch):
    queued = []
    monkeypatch.setattr("app.tasks.train_run", lambda run_id: queued.append(run_id))
    with app.app_context():
        lease = app.config["TRAINING_LEASE_S"]
        dead, alive, release = running(lease + 60), running(lease - 60), running(lease + 60, FoldsMode.RELEASED)
    hosts = [app, app_with(STORAGE_URL=storage_url, CACHE_ROOT=str(tmp_path / "host-b" / "cache"))]
    together = threading.Barrier(len(hosts))
    taken, errors = [], []

    def take(host) -> None:
        try:
            with host.app_context():
                together.wait()
                taken.extend(training.take_over_stopped_runs())
        except Exception as exc:  # shown by the assertion below
            errors.append(exc)

    threads = [threading.Thread(target=take, args=(host,)) for host in hosts]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == [] and taken == queued == [dead]
    with app.app_context():
        run = db.session.get(TrainingRun, dead)
        assert run.status is RunStatus.QUEUED and run.message.startswith("resumed after its worker stopped at ")
        assert len(run.config["worker_stopped"]) == 1
        assert db.session.get(TrainingRun, alive).status is RunStatus.RUNNING
        gone = db.session.get(TrainingRun, release)  # a conversion keeps no partial state: it says to import again
        assert gone.status is RunStatus.FAILED and "import the weights again" in gone.message
        assert training.take_over_stopped_runs() == []  # nothing is taken twice
    page = admin_client.get(f"/training/runs/{dead}").get_data(as_text=True)
    assert "after its worker stopped at" in page


def test_only_the_attempt_that_claimed_a_run_renews_its_lease(app):
    from app.services.training.control import claim_run, renew_lease

    with app.app_context():
        run = db.session.get(TrainingRun, running(0))
        first = run.started_at
        assert renew_lease(run.id, first)
        db.session.execute(update(TrainingRun).where(TrainingRun.id == run.id).values(status=RunStatus.QUEUED))
        assert claim_run(run, "loading frames") and run.started_at != first  # another worker's attempt
        assert not renew_lease(run.id, first) and renew_lease(run.id, run.started_at)
