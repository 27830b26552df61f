"""The documentation keeps its promises: every ``flask`` command it shows
exists with the options it uses, every relative link and repository path it
names exists, and the front page stays a front page."""

import re
from pathlib import Path

import pytest
from click.testing import CliRunner
from flask.cli import FlaskGroup

from app import create_app

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)
SPAN = re.compile(r"`([^`\n]*(?:\n[^`\n]+)*)`")  # a code span may wrap onto the next lines
FLASK = re.compile(r"(?:^|\s)(?:\S*/)?flask\s+(.*)")  # flask, .venv/bin/flask, python -m flask
OPTION = re.compile(r"(?<![\w/=-])--?[A-Za-z][\w-]*")
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
REPO_PATH = re.compile(r"^(?:app|egonet|bench|tests|static|templates|migrations|docs)/[\w./-]*$")


def text(page: Path) -> str:
    return page.read_text(encoding="utf-8")


def prose(page: Path) -> str:
    """The page without its fenced blocks."""
    return FENCE.sub("", text(page))


def commands(page: Path) -> list[str]:
    """Every ``flask ...`` command of the page: fenced lines (continuations
    joined, comments and ``&&`` chains split) and code spans."""
    found = []
    for block in FENCE.findall(text(page)):
        for line in block.replace("\\\n", " ").splitlines():
            for part in line.split("&&"):
                if match := FLASK.search(re.split(r"\s#\s", part)[0]):
                    found.append(match.group(1))
    for span in SPAN.findall(prose(page)):
        span = " ".join(span.split())
        if span.startswith("flask "):
            found.append(span[len("flask ") :])
    return [" ".join(c.replace("--app app", "").split()) for c in found]


CASES = sorted({(page.relative_to(ROOT).as_posix(), c) for page in PAGES for c in commands(page)})


@pytest.fixture(scope="module")
def flask_cli(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("docs")
    app = create_app({"TESTING": True, "SECRET_KEY": "docs", "SQLALCHEMY_DATABASE_URI": f"sqlite:///{tmp / 'db.sqlite3'}"},
                     instance_path=str(tmp))
    return FlaskGroup(create_app=lambda: app)


def test_the_docs_show_commands():
    assert len(CASES) > 40 and any(c.startswith("egonet train") for _, c in CASES)


@pytest.mark.parametrize(("page", "command"), CASES, ids=[f"{p}: {c}" for p, c in CASES])
def test_every_command_exists_with_the_options_it_uses(flask_cli, page, command):
    words = command.replace("[", " ").replace("]", " ").split()
    path = words[: next((i for i, w in enumerate(words) if not re.fullmatch(r"[a-z][a-z0-9-]*", w)), len(words))]
    result = CliRunner().invoke(flask_cli, [*path, "--help"])
    assert result.exit_code == 0, f"{page}: flask {command}\n{result.output}"
    unknown = [o for o in OPTION.findall(command) if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", result.output)]
    assert not unknown, f"{page}: flask {command} uses {unknown}, which `flask {' '.join(path)} --help` does not list"


def slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    return {slug(h) for h in re.findall(r"^#+ (.*)$", prose(page), re.M)}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_and_repository_path_exists(page):
    broken = []
    for target in LINK.findall(prose(page)):
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        linked = (page.parent / file).resolve() if file else page
        if not linked.exists() or (anchor and linked.suffix == ".md" and anchor not in anchors(linked)):
            broken.append(target)
    broken += [s for s in SPAN.findall(prose(page)) if REPO_PATH.match(s) and not (ROOT / s).exists()]
    assert not broken, f"{page.relative_to(ROOT)}: nothing at {broken}"


def test_the_readme_is_a_front_page():
    assert len(text(ROOT / "README.md").splitlines()) <= 300
