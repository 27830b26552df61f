"""Where the browser tests find Chromium, and what they say without one (no browser needed)."""

import pytest

from tests.browser.conftest import find_chromium


def executable(folder, name: str) -> str:
    path = folder / name
    path.write_text("#!/bin/sh\n")
    path.chmod(0o755)
    return str(path)


def test_a_chromium_named_in_the_environment_wins_over_the_path(tmp_path):
    on_path = executable(tmp_path, "chromium")
    (tmp_path / "elsewhere").mkdir()
    named = executable(tmp_path / "elsewhere", "my-chromium")
    assert find_chromium({"PATH": str(tmp_path)}) == on_path
    assert find_chromium({"PATH": str(tmp_path), "CHROMIUM": named}) == named
    assert find_chromium({"PATH": str(tmp_path), "PLAYWRIGHT_CHROMIUM": named, "CHROMIUM": on_path}) == named
    assert find_chromium({"PATH": str(tmp_path / "elsewhere"), "CHROMIUM": "my-chromium"}) == named


def test_debians_other_name_is_found_too(tmp_path):
    found = executable(tmp_path, "chromium-browser")
    assert find_chromium({"PATH": str(tmp_path)}) == found


def test_without_chromium_the_tests_skip_naming_the_install_command(tmp_path):
    with pytest.raises(pytest.skip.Exception) as skipped:
        find_chromium({"PATH": str(tmp_path)})
    reason = str(skipped.value)
    assert "apt-get install -y chromium" in reason and "\n" not in reason
    with pytest.raises(pytest.skip.Exception, match="'/nowhere/chromium'.*apt-get install -y chromium"):
        find_chromium({"PATH": str(tmp_path), "CHROMIUM": "/nowhere/chromium"})


def test_without_chromium_a_required_browser_fails(tmp_path):
    with pytest.raises(pytest.fail.Exception, match="apt-get install -y chromium.*EGONET_REQUIRE_BROWSER=1"):
        find_chromium({"PATH": str(tmp_path), "EGONET_REQUIRE_BROWSER": "1"})
