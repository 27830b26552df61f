"""The house: which room may import which, and no import goes round in a circle.

Read from the source (every ``import``/``from`` statement, at module level or
inside a function), so neither a forbidden import nor a circle can hide in a
function body. ``from pkg import name`` imports the submodule ``pkg.name`` when
there is one and the package's ``__init__`` otherwise, as Python does.
"""

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Rooms from the top of the house down; an import may point down or stay in
# its room, never up. The first matching prefix names a module's room.
LAYERS = [
    ("entry points", ("app", "app.cli", "app.tasks")),
    ("web", ("app.blueprints", "app.forms", "app.security")),
    ("services", ("app.services",)),
    ("data and plumbing", ("app.models", "app.extensions", "app.errors", "app.validation",
                           "app.limits", "app.queue", "app.throttle", "app.spreadsheet", "app.version")),
    ("science", ("egonet",)),
]


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def python_modules() -> dict[str, Path]:
    return {module_name(p): p for top in ("app", "egonet") for p in sorted((ROOT / top).rglob("*.py"))}


def imports_of(path: Path, known: dict[str, Path]) -> set[str]:
    """The project modules ``path`` imports."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
            origin = ".".join([*base, node.module] if node.module else base)
            for alias in node.names:
                sub = f"{origin}.{alias.name}"
                found.add(sub if sub in known else origin)
    return {m for m in found if m in known}


def room_of(module: str) -> int:
    best = max((p for _, prefixes in LAYERS for p in prefixes if module == p or module.startswith(p + ".")), key=len)
    return next(i for i, (_, prefixes) in enumerate(LAYERS) if best in prefixes)


def graph() -> dict[str, set[str]]:
    known = python_modules()
    return {name: imports_of(path, known) - {name} for name, path in known.items()}


JS_IMPORT = re.compile(r"""(?:^|\n)\s*(?:import|export)\b[^'"`;]*?\bfrom\s*['"](\.[^'"]+)['"]|import\s*\(\s*['"](\.[^'"]+)['"]""")


def js_graph() -> dict[str, set[str]]:
    folder = ROOT / "static" / "js"
    edges = {}
    for path in sorted(folder.glob("*.js")):
        targets = {a or b for a, b in JS_IMPORT.findall(path.read_text())}
        edges[path.name] = {(path.parent / t).resolve().name for t in targets}
    return edges


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_every_import_points_down():
    upward = [
        f"{a} ({LAYERS[room_of(a)][0]}) imports {b} ({LAYERS[room_of(b)][0]})"
        for a, targets in graph().items()
        for b in sorted(targets)
        if room_of(b) < room_of(a)
    ]
    assert not upward, "; ".join(upward)


@pytest.mark.parametrize("kind", ["python", "static-js"])
def test_no_import_circle(kind):
    found = circles(graph() if kind == "python" else js_graph())
    assert not found, " | ".join(" <-> ".join(c) for c in found)


def test_egonet_imports_no_web_stack():
    offences = [
        f"{module_name(p)} imports {n.names[0].name if isinstance(n, ast.Import) else n.module}"
        for p in sorted((ROOT / "egonet").rglob("*.py"))
        for n in ast.walk(ast.parse(p.read_text()))
        if isinstance(n, (ast.Import, ast.ImportFrom))
        and any(
            (a.name if isinstance(n, ast.Import) else (n.module or "")).split(".")[0]
            in ("app", "flask", "sqlalchemy", "flask_sqlalchemy")
            for a in n.names
        )
    ]
    assert not offences, "; ".join(offences)


def test_the_reader_sees_circles_inside_functions_and_packages(tmp_path, monkeypatch):
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    (tmp_path / "app" / "services").mkdir(parents=True)
    (tmp_path / "app" / "__init__.py").write_text("MAX_ID = 1\ndef create():\n    from app.services import x\n")
    (tmp_path / "app" / "services" / "__init__.py").write_text("")
    (tmp_path / "app" / "services" / "x.py").write_text("from .. import MAX_ID\n")
    (tmp_path / "egonet").mkdir()
    assert circles(graph()) == [["app", "app.services.x"]]


def test_js_reader_sees_both_import_forms():
    sample = "import { a } from './one.js';\nexport { b } from './two.js';\nconst c = await import('./three.js');\n"
    assert {a or b for a, b in JS_IMPORT.findall(sample)} == {"./one.js", "./two.js", "./three.js"}


def room(module: str) -> str:
    """A folder of the house: a room prefix, services and egonet by sub-package."""
    best = max((p for _, prefixes in LAYERS for p in prefixes if module == p or module.startswith(p + ".")), key=len)
    rest = module[len(best) + 1 :].split(".")[0] if module != best else ""
    if best in ("app.services", "egonet") and rest and (ROOT / best.replace(".", "/") / rest).is_dir():
        return f"{best}.{rest}"
    return best


def house_picture() -> str:
    """docs/architecture.md's picture: rooms by floor, imports between rooms as arrows."""
    arrows = sorted({(room(a), room(b)) for a, targets in graph().items() for b in targets if room(a) != room(b)})
    lines = ["```mermaid", "flowchart TD"]
    for i, (floor, _) in enumerate(LAYERS):
        rooms = sorted({room(m) for m in graph() if room_of(m) == i})
        lines += [f'  subgraph floor{i}["{floor}"]', *(f'    {r.replace(".", "_")}["{r}"]' for r in rooms), "  end"]
    lines += [f"  {a.replace('.', '_')} --> {b.replace('.', '_')}" for a, b in arrows]
    return "\n".join([*lines, "```"]) + "\n"


def test_the_house_picture_is_current():
    doc = (ROOT / "docs" / "architecture.md").read_text()
    assert house_picture() in doc, "redraw it: python -c 'from tests.test_layers import house_picture as h; print(h())'"
