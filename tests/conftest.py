"""Shared fixtures, kept minimal.

Compiled training steps are cached per system object, so the training tests of several files
share one harmonic-oscillator instance (fewer compilations, a faster suite).
"""

from __future__ import annotations

import pytest

from atlasnn.compile_cache import clear_programs
from atlasnn.systems import harmonic_oscillator


@pytest.fixture
def x64():
    """JAX in float64 for the test (the traced solve and the learning need it; JAX's default is off)."""
    import jax

    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="session")
def ho():
    """H = p²/2 + x²/2 with z0 = (1, 0); exact solution x = cos t, p = −sin t."""
    return harmonic_oscillator()


@pytest.fixture(autouse=True, scope="module")
def _drop_compiled_programs():
    """After each test file, drop the compiled programs it made (atlasnn.compile_cache.clear_programs):
    one process compiling every program of the suite ran out of memory maps (vm.max_map_count) and
    crashed inside XLA near the end of the suite."""
    yield
    clear_programs()


#: the test files of minutes each (the docs' blocks): first in the run, so that under pytest-xdist's
#: ``--dist loadfile --no-loadscope-reorder`` (what ``make test-all`` runs) the workers start on them
#: and the short files fill in the end, instead of a worker running a long file alone at the end
LONG_FILES = ("test_docs.py", "test_docs_pages_1.py", "test_docs_pages_2.py")


def pytest_collection_modifyitems(items):
    """The long files first, then the others by their number of tests (most first, as xdist's own
    reordering would); each file's tests keep their order."""
    count: dict = {}
    for item in items:
        count[item.path] = count.get(item.path, 0) + 1
    items.sort(key=lambda item: (item.path.name not in LONG_FILES, -count[item.path]))
