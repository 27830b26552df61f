import time
from types import SimpleNamespace

import pytest

from app.services import media
from app.services.importing import import_path
from app.services.storage import store
from tests.app.factories import image_folder

pytestmark = pytest.mark.both_storages


def remove_orphans(runner, monkeypatch, *, orphans: int) -> str:
    """``media-check --remove-orphans`` keeps ``orphans`` files within the grace (a transaction may still be
    writing them) and removes them once it has passed; the second run's output."""
    result = runner.invoke(args=["egonet", "media-check", "--remove-orphans"])
    assert f"{orphans} orphaned, 0 removed" in result.output, result.output
    later = time.time() + 7200
    monkeypatch.setattr(media, "time", SimpleNamespace(time=lambda: later))
    result = runner.invoke(args=["egonet", "media-check", "--remove-orphans"])
    assert result.exit_code == 0, result.output
    return result.output


def test_media_check_finds_orphans_and_missing_files(ctx, runner, tmp_path, monkeypatch):
    import_path(image_folder(tmp_path / "rec", n=2, depth=True), activity="cooking")
    result = runner.invoke(args=["egonet", "media-check"])
    assert result.exit_code == 0 and "4 files, 4 referenced, 0 missing, 0 orphaned" in result.output

    orphan = media.store(b"written before a crash", ".png")
    assert "5 files, 4 referenced, 0 missing, 1 orphaned, 1 removed" in remove_orphans(runner, monkeypatch, orphans=1)
    assert not store().exists(f"media/{orphan}") and len(list(store().list("media"))) == 4

    victim = sorted(media.referenced_paths())[0]
    store().delete(f"media/{victim}")
    result = runner.invoke(args=["egonet", "media-check"])
    assert result.exit_code == 1 and f"missing: {victim}" in result.output
