"""The measured tables of the Benchmarks pages (SOLVER_MEASURED, SPLITTING_MEASURED, PDE_MEASURED,
BENCHMARKS, …) are what scripts/solver_doc.py makes from the committed records: no number there can
drift from its record. The key numbers of the prose around them (BENCHMARKS, LIMITATIONS,
DIFFRAX_MEASURED, SOLVER_MEASURED) and the machines PERFORMANCE.md names are checked against their
records by the same script."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_solver_pages_hold_what_their_records_make():
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "solver_doc.py"), "--check"], capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stdout + out.stderr
