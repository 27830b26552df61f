"""How ``tests/conftest.py`` runs the suite: what the README promises of ``--all``'s workers."""

import os
import subprocess
import sys

import pytest


def test_an_xdist_worker_and_what_it_starts_compute_on_one_thread():
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        pytest.skip("only in a pytest-xdist worker (--all, or -n N)")
    import cv2
    import torch

    assert (torch.get_num_threads(), cv2.getNumThreads()) == (1, 1)
    child = "import cv2, threadpoolctl, torch; print(torch.get_num_threads(), max(p['num_threads'] for p in threadpoolctl.threadpool_info()))"
    out = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["1", "1"]
