"""egonet is the science: importing it must not load the web app's stack."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_importing_egonet_loads_neither_flask_nor_sqlalchemy():
    code = (
        "import importlib, pkgutil, sys, egonet\n"
        "for m in pkgutil.walk_packages(egonet.__path__, 'egonet.'):\n"
        "    importlib.import_module(m.name)\n"
        "bad = [m for m in ('flask', 'sqlalchemy', 'flask_sqlalchemy', 'app') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"egonet imported {out.stdout.strip()}"


IMPORT_EVERYTHING = """
import importlib, json, pkgutil, socket, sqlite3, sys

sys.path.insert(0, sys.argv[1])
opened = []


def refuse(kind):
    def refused(*args, **kwargs):
        opened.append(f"{kind} {args[1:] or args}")
        raise OSError(f"{kind} opened while importing")

    return refused


socket.socket.connect = socket.socket.connect_ex = refuse("socket")
sqlite3.connect = refuse("sqlite")


def fail(name):
    raise


for package in ("app", "egonet"):
    root = importlib.import_module(package)
    for module in pkgutil.walk_packages(root.__path__, package + ".", onerror=fail):
        importlib.import_module(module.name)
print(json.dumps(opened))
"""


def files_under(folder: Path) -> set[Path]:
    return set(folder.rglob("*")) if folder.exists() else set()


def test_importing_any_module_creates_no_file_and_opens_no_connection(tmp_path):
    instance = ROOT / "instance"
    before = files_under(instance)
    out = subprocess.run(
        [sys.executable, "-c", IMPORT_EVERYTHING, str(ROOT)], cwd=tmp_path, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip() == "[]", f"connections opened on import: {out.stdout.strip()}"
    assert list(tmp_path.iterdir()) == []
    assert files_under(instance) == before
