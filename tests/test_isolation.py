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
