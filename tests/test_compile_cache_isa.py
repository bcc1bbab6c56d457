"""The persistent compilation cache keeps a program per instruction set: XLA_FLAGS (where
``--xla_cpu_max_isa`` limits the CPU's instruction set, as `make test-isa` does) is part of JAX's
cache key, so a run limited to AVX2 or SSE4.2 is never served machine code compiled for another
set, and the suite's runs under each set may share one cache directory."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

SCRIPT = ("import atlasnn, jax, jax.numpy as jnp\n"
          "def isa_probe(x):\n    return jnp.sin(x) * 2.0 + jnp.cos(x)\n"
          "jax.jit(isa_probe)(jnp.arange(7.0)).block_until_ready()\n")


def _compile(cache, flags):
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.update({"ATLASNN_CACHE_DIR": str(cache), **({"XLA_FLAGS": flags} if flags else {})})
    subprocess.run([sys.executable, "-c", SCRIPT], env=env, check=True, capture_output=True, timeout=300)
    return sorted(p.name for p in cache.glob("jit_isa_probe-*-cache"))


@pytest.mark.long
def test_a_program_is_kept_per_instruction_set(tmp_path):
    avx2 = _compile(tmp_path, "--xla_cpu_max_isa=AVX2")
    assert len(avx2) == 1
    assert _compile(tmp_path, "--xla_cpu_max_isa=AVX2") == avx2  # the same set: served from the cache
    sse = _compile(tmp_path, "--xla_cpu_max_isa=SSE4_2")
    assert len(sse) == 2  # another set: compiled and kept beside the first
    assert len(_compile(tmp_path, None)) == 3  # the machine's own set: a third
