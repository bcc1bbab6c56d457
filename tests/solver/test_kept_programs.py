"""The march program served from its exported form on disk (atlasnn/solver/_exported.py): the same
numbers bit for bit as the traced program, one file per computation, a damaged file replaced, and
systems not defined by data (a Python function) never served from disk."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn import solve
from atlasnn.compile_cache import CACHE_ENV, clear_programs
from atlasnn.systems import HamiltonianSystem, henon_heiles

T = 3.0
GRID = np.linspace(0.0, T, 101)


def _solve(system):
    clear_programs()  # a new process, as far as atlasnn's programs go
    return solve(system, None, (0.0, T), rtol=1e-10, atol=1e-12)(GRID)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    return tmp_path / "exported"


@pytest.mark.long
def test_the_exported_program_gives_the_traced_programs_numbers(cache, monkeypatch):
    first = _solve(henon_heiles())
    files = sorted(cache.glob("march-*.bin"))
    assert len(files) == 1
    stamp = files[0].stat().st_mtime_ns
    again = _solve(henon_heiles())  # read back from the file, not exported again
    assert files[0].stat().st_mtime_ns == stamp
    monkeypatch.setenv(CACHE_ENV, "off")
    traced = _solve(henon_heiles())
    assert np.array_equal(first, traced) and np.array_equal(again, traced)


@pytest.mark.long
def test_another_computation_gets_its_own_file_and_a_damaged_file_is_replaced(cache):
    _solve(henon_heiles())
    other = _solve(henon_heiles(lam=0.7))
    files = sorted(cache.glob("march-*.bin"))
    assert len(files) == 2
    for f in files:
        f.write_bytes(b"not a program")
    assert np.array_equal(_solve(henon_heiles(lam=0.7)), other)
    damaged = [f.read_bytes() == b"not a program" for f in cache.glob("march-*.bin")]
    assert sorted(damaged) == [False, True]  # the one read again was made again; the other waits


def test_a_system_given_as_a_python_function_is_never_served_from_disk(cache):
    hh = henon_heiles()
    plain = HamiltonianSystem(hh.hamiltonian, 2, name="mine", q_names=hh.q_names, p_names=hh.p_names,
                              z0=hh.z0, separable=True)
    assert plain.spec is None
    assert np.allclose(_solve(plain), _solve(hh), rtol=0, atol=1e-12)
    assert len(list(cache.glob("march-*.bin"))) == 1  # only the built-in's
