"""The one handler: a Problem or EgonetError raised anywhere reaches the user in one shape.

The views and the command below are throwaways registered on the test's
app, so the handlers are tested without relying on any product view.
"""

from pathlib import Path

import click
import pytest

from app.errors import Problem
from app.security import public
from egonet.errors import EgonetError
from egonet.io import MediaError

JSON = {"Accept": "application/json"}
HTML = {"Accept": "text/html"}


@pytest.fixture
def raising_app(app):
    def egonet_error():
        raise EgonetError("radius: must be a positive number of pixels, got -1", field="radius")

    def problem():
        raise Problem("no such frame", status=404)

    def broken_media():
        raise MediaError(Path(app.config["STORAGE_URL"]) / "media" / "ab" / "abc.png", "not a readable image (corrupt or unknown format)")

    app.add_url_rule("/_test/egonet-error", view_func=public(egonet_error))
    app.add_url_rule("/_test/broken-media", view_func=public(broken_media))
    app.add_url_rule("/_test/problem", view_func=public(problem))
    return app


def test_egonet_error_in_a_view_is_a_400_naming_the_field(raising_app):
    response = raising_app.test_client().get("/_test/egonet-error", headers=JSON)
    assert response.status_code == 400
    assert response.get_json() == {
        "error": "bad_request",
        "message": "radius: must be a positive number of pixels, got -1",
        "fields": {"radius": "must be a positive number of pixels, got -1"},
    }


def test_egonet_error_in_a_page_is_the_html_error_page(raising_app):
    response = raising_app.test_client().get("/_test/egonet-error", headers=HTML)
    assert response.status_code == 400
    assert response.mimetype == "text/html"
    page = response.get_data(as_text=True)
    assert "radius: must be a positive number of pixels, got -1" in page
    assert "<code>radius</code>" in page


def test_a_broken_stored_file_is_the_servers_fault_and_its_path_stays_private(raising_app):
    response = raising_app.test_client().get("/_test/broken-media", headers=JSON)
    assert response.status_code == 500
    assert response.get_json()["error"] == "internal_server_error"
    assert raising_app.config["STORAGE_URL"] not in response.get_data(as_text=True)


def test_problem_in_a_view_keeps_its_status(raising_app):
    response = raising_app.test_client().get("/_test/problem", headers=JSON)
    assert response.status_code == 404
    assert response.get_json() == {"error": "not_found", "message": "no such frame", "fields": {}}


@pytest.fixture
def egonet_group(app):
    """The ``flask egonet`` group, with throwaway commands removed again afterwards."""
    group = app.cli.commands["egonet"]
    before = set(group.commands)
    yield group
    for name in set(group.commands) - before:
        del group.commands[name]


@pytest.mark.parametrize(
    "error",
    [Problem("the activity 'x' has no frames", field="activity"), EgonetError("sigma must be positive", field="sigma")],
    ids=["problem", "egonet"],
)
def test_an_error_in_a_command_is_one_line_and_exit_1(app, egonet_group, error):
    @egonet_group.command("_test-fail")
    def fail():
        click.echo("started")
        raise error

    result = app.test_cli_runner().invoke(args=["egonet", "_test-fail"])
    assert result.exit_code == 1
    assert result.output == f"started\nError: {error}\n"
