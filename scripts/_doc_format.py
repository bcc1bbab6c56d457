"""Number formats shared by the table makers of ``scripts/solver_doc.py``."""

from __future__ import annotations


def milliseconds(seconds: float) -> str:
    """A time as "12.3 ms", or in seconds from one second up."""
    ms = seconds * 1e3
    return f"{ms:.3g} ms" if ms < 1000 else f"{seconds:.3g} s"
