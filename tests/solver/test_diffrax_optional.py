"""atlasnn without Diffrax: nothing but atlasnn.solver.diffrax imports it, and that module says in one
line which extra to install (checked with Diffrax hidden, installed or not)."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import sys
sys.modules["diffrax"] = None  # as if it were not installed: importing it raises ImportError
import atlasnn, atlasnn.solver, atlasnn.solutions
from atlasnn import solve
from atlasnn.solver import GaussCollocation
try:
    import atlasnn.solver.diffrax
except ImportError as exc:
    print("refused:", exc)
"""


def test_atlasnn_works_without_diffrax_and_the_extra_is_named():
    proc = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and "pip install diffrax" in lines[0], proc.stdout
