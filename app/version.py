"""The code version reports name: the package's version, and ``git describe`` when running from a checkout.

A leaf: imports nothing of the app. Asked lazily (never at import time) and
once per process.
"""

import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "egonet-studio"


@lru_cache(maxsize=1)
def code_version() -> str:
    """``"egonet-studio 0.1.0 (git 4c29c1a-dirty)"`` in a checkout, ``"egonet-studio 0.1.0"`` in an installed copy."""
    try:
        version = f"{PACKAGE} {metadata.version(PACKAGE)}"
    except metadata.PackageNotFoundError:
        version = f"{PACKAGE} (version unknown: not installed)"
    if not (ROOT / ".git").exists():
        return version
    try:
        described = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--tags"], cwd=ROOT, capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return version
    return f"{version} (git {described})" if described else version
