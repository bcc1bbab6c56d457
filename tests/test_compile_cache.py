"""The persistent compilation cache: where it lives, how it is turned off, that it is written."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from atlasnn.compile_cache import CACHE_ENV, cache_dir


@pytest.mark.parametrize("value", ["off", "0", "none", "", "OFF"])
def test_off_values_turn_the_cache_off(monkeypatch, value):
    monkeypatch.setenv(CACHE_ENV, value)
    assert cache_dir() is None


def test_given_directory_and_default(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "c"))
    assert cache_dir() == tmp_path / "c"
    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache_dir() == tmp_path / "atlasnn" / "jax"


_PROGRAM = """
import atlasnn, jax, jax.numpy as jnp
print(jax.config.jax_compilation_cache_dir)
jax.jit(lambda x: jnp.cos(x) * 3.0 - x)(jnp.arange(5.0)).block_until_ready()
"""


def _run(env_value):
    env = dict(os.environ, **{CACHE_ENV: env_value})
    return subprocess.run([sys.executable, "-c", _PROGRAM], env=env, capture_output=True, text=True, check=True)


def test_a_compiled_program_is_written_to_the_cache(tmp_path):
    folder = tmp_path / "jax-cache"
    out = _run(str(folder))
    assert out.stdout.strip() == str(folder)
    assert any(folder.iterdir()), "no cache entry written"


def test_an_unwritable_directory_is_skipped(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    out = _run(str(blocker / "cache"))  # cannot be created: the run goes on without a cache
    assert out.stdout.strip() in ("", "None")


def test_the_cache_is_locked_so_two_processes_can_share_it(tmp_path):
    """With a size limit JAX takes a file lock around every read and write of the cache (without
    it a reader could load a half-written entry: two segmentation faults here); the lock file is
    the proof that the locked path is taken."""
    folder = tmp_path / "jax-cache"
    _run(str(folder))
    assert (folder / ".lockfile").exists()


def test_clear_programs_drops_the_compiled_programs_held_in_memory(ho):
    """A long process must be able to let go of its compiled programs (each holds memory maps)."""
    import numpy as np

    from atlasnn import solve
    from atlasnn.compile_cache import clear_programs
    from atlasnn.solver import _gauss_march

    solve(ho, [1.0, 0.0], (0.0, 1.0))  # the default solver: the Gauss collocation's march
    assert _gauss_march._cached.cache_info().currsize >= 1
    clear_programs()
    assert _gauss_march._cached.cache_info().currsize == 0
    assert np.isfinite(solve(ho, [1.0, 0.0], (0.0, 1.0))(0.5)).all()  # and compiles again when needed


def test_compile_lowered_passes_xla_options_and_drops_one_this_xla_lacks():
    import jax
    import jax.numpy as jnp
    import numpy as np

    from atlasnn.compile_cache import compile_lowered
    from atlasnn.training import training_compiler_options

    x = jnp.linspace(0.0, 1.0, 17)
    lowered = jax.jit(lambda v: jnp.sin(v) * v + 1).lower(x)
    want = np.asarray(lowered.compile()(x))
    legacy = training_compiler_options()
    assert legacy == ({"xla_cpu_use_fusion_emitters": False} if jax.default_backend() == "cpu" else None)
    for options in (legacy, {"xla_no_such_option_in_any_version": True}, None):
        np.testing.assert_allclose(np.asarray(compile_lowered(lowered, options)(x)), want, rtol=1e-6)
    with pytest.raises(Exception):  # JAX itself refuses the unknown option: compile_lowered catches it
        lowered.compile(compiler_options={"xla_no_such_option_in_any_version": True})


def test_a_packed_program_returns_what_the_program_does_array_for_array():
    """packed_program: arguments and results of several dtypes and shapes (0-d, bool, integers, a
    large block) cross as one flat array per dtype and come back as the program's own."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from atlasnn.compile_cache import packed_program

    def program(t, z, L, count, flag):
        out = (z * t, jnp.sum(L, axis=0), count + 1, ~flag, L * 2.0, jnp.asarray(t > 0), count * z.shape[0])
        return list(out)

    rng = np.random.default_rng(3)
    with jax.enable_x64(True):
        args = [np.float64(0.5), rng.normal(size=4), rng.normal(size=(300, 3, 4)), np.int64(7), np.array([True, False])]
        run = packed_program(program, args)
        for call in (args, [np.float64(-2.0), rng.normal(size=4), rng.normal(size=(300, 3, 4)), np.int64(-1),
                            np.array([False, False])]):
            got, want = run(*call), [np.asarray(x) for x in jax.jit(program)(*call)]
            assert len(got) == len(want)
            for g, w in zip(got, want):
                assert g.shape == w.shape and g.dtype == w.dtype
                np.testing.assert_array_equal(g, w)
