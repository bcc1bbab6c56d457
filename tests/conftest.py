"""Shared fixtures, kept minimal.

Compiled training steps are cached per system object, so the training tests of several files
share one harmonic-oscillator instance (fewer compilations, a faster suite).
"""

from __future__ import annotations

import pytest

from atlasnn.systems import harmonic_oscillator


@pytest.fixture(scope="session")
def ho():
    """H = p²/2 + x²/2 with z0 = (1, 0); exact solution x = cos t, p = −sin t."""
    return harmonic_oscillator()
