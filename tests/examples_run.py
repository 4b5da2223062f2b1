"""Run a script of ``examples/`` headless, as the tests that check the examples do."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def run_example(script: str, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run ``examples/script`` with ``args`` from the checkout (Agg backend, the checkout on PYTHONPATH)."""
    return subprocess.run([sys.executable, str(ROOT / "examples" / script), *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT)))
