"""The layers of the README's Layout section: who may import whom.

Read from the source (every ``import``/``from`` statement, module level or
inside a function), so a forbidden import cannot hide in a function body.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def imports_of(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def modules(folder: str) -> list[Path]:
    return sorted((ROOT / folder).rglob("*.py")) if (ROOT / folder).is_dir() else [ROOT / folder]


# (files, forbidden module prefixes, why)
RULES = [
    ("egonet", ("app", "flask", "sqlalchemy", "flask_sqlalchemy"), "egonet is the science: arrays in, arrays out"),
    ("app/models", ("app.services", "app.blueprints", "app.cli", "app.tasks", "app.queue"), "models know no verb"),
    ("app/queue.py", ("app.services", "app.blueprints", "app.cli", "app.tasks", "app.models"), "the queue is a leaf"),
    ("app/services", ("app.blueprints", "app.cli", "app.tasks"), "services are called, they do not call views"),
    ("app/blueprints", ("app.cli", "app.tasks"), "views call services"),
]


@pytest.mark.parametrize(("folder", "forbidden", "why"), RULES, ids=[r[0] for r in RULES])
def test_no_module_imports_across_its_layer(folder, forbidden, why):
    offences = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in modules(folder)
        for name in sorted(imports_of(path))
        if any(name == f or name.startswith(f + ".") for f in forbidden)
    ]
    assert not offences, f"{why}: " + "; ".join(offences)


def test_the_rules_see_imports_inside_functions(tmp_path):
    sample = tmp_path / "m.py"
    sample.write_text("def f():\n    from app.services import media\n    import flask\n")
    assert imports_of(sample) == {"app.services", "flask"}
