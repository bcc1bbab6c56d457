"""atlasnn.limits: memory estimates of a training and of an integration, and one-line refusals."""

from __future__ import annotations

import json
import subprocess
import sys

import jax
import pytest

from atlasnn.errors import ConfigError
from atlasnn.limits import (
    BASE_BYTES,
    GIB,
    MIB,
    available_memory,
    check_integration_memory,
    check_training_memory,
    estimate_integration_memory,
    estimate_training_memory,
    parameter_count,
)
from atlasnn.nn import make_model

MACHINE_24_GIB = 24 * GIB


@pytest.mark.parametrize("width, depth, d", [(50, 2, 1), (80, 2, 2), (7, 1, 3), (16, 4, 1)])
def test_parameter_count_is_the_networks(width, depth, d):
    model = make_model([0.1] * (2 * d), scaling="exp_decay", width=width, depth=depth)
    leaves = jax.tree_util.tree_leaves(model.net)
    assert parameter_count(width, depth, 2 * d) == sum(x.size for x in leaves)


def test_the_estimate_grows_as_the_rule_says():
    one = estimate_training_memory(100_000, 50, 2, 2)
    assert estimate_training_memory(200_000, 50, 2, 2) - one == pytest.approx(100_000 * (21 * 100 + 22 * 2), abs=2)
    assert estimate_training_memory(100_000, 50, 2, 2, seeds=3) - BASE_BYTES == pytest.approx(3 * (one - BASE_BYTES), abs=3)
    assert estimate_training_memory(100_000, 50, 2, 2, dtype_bytes=8) - BASE_BYTES == pytest.approx(
        2 * (one - BASE_BYTES), abs=2)
    # the measured points of the module docstring: 2 419 MiB at K = 1e6 (50x2, 2d = 2)
    assert 2419 * MIB <= estimate_training_memory(1_000_000, 50, 2, 2) <= 1.05 * 2419 * MIB
    assert estimate_integration_memory(1_000_000, 2) == 1_000_000 * (130 + 77 * 2)


def test_a_training_that_cannot_fit_in_24_gib_is_refused():
    with pytest.raises(ConfigError) as info:
        check_training_memory(1_000_000, 1000, 2, 2, available=MACHINE_24_GIB)
    msg = str(info.value)
    assert msg == ("train.n_points = 1000000: a training needs about 39.7 GiB, more than the 24 GiB available "
                   "(K = 1000000, network 1000x2, 2d = 2); lower train.n_points or network.width")
    with pytest.raises(ConfigError, match=r"^target\.train\.n_points = 500000: a training of 4 seeds together"):
        check_training_memory(500_000, 80, 2, 4, seeds=4, key="target.train.n_points", available=2 * GIB)


def test_the_largest_k_at_the_papers_width_fits_in_24_gib():
    need = check_training_memory(1_000_000, 50, 2, 2, available=MACHINE_24_GIB)
    assert 2 * GIB < need < 3 * GIB
    assert check_training_memory(1_000_000, 80, 2, 4, available=MACHINE_24_GIB) < 4 * GIB


def test_the_fine_symplectic_euler_run_of_k_1e6_is_refused():
    steps = (1_000_000 - 1) * 100  # K - 1 steps, fine_factor 100: the MemoryError of the issue
    with pytest.raises(ConfigError) as info:
        check_integration_memory(steps, 2, value=100, available=MACHINE_24_GIB)
    assert str(info.value) == ("evaluation.fine_factor = 100: the integration of 99999900 steps and its reference "
                               "need about 26.4 GiB, more than the 24 GiB available; lower evaluation.fine_factor")
    assert check_integration_memory((1_000_000 - 1) * 10, 2, available=MACHINE_24_GIB) < 3 * GIB


def test_bad_arguments_and_unknown_memory():
    with pytest.raises(ConfigError, match="n_points = 0: must be an integer >= 1"):
        estimate_training_memory(0, 50, 2, 2)
    with pytest.raises(ConfigError, match="dtype_bytes"):
        estimate_training_memory(10, 50, 2, 2, dtype_bytes=2)
    room = available_memory()
    assert room is None or room > 0
    if room is not None:  # this process is running, so its own small training fits
        check_training_memory(200, 50, 2, 2)


@pytest.mark.slow
def test_the_estimate_against_a_measured_peak():
    """Peak RSS of real trainings (fresh processes) against the estimate: within -5 % ... +15 %."""
    for K in (2, 200_000):
        done = subprocess.run([sys.executable, "-m", "benchmarks.memory", "--one", "train", str(K), "50", "2", "1"],
                              capture_output=True, text=True, check=True)
        peak = json.loads(done.stdout.strip().splitlines()[-1])["peak_MiB"] * MIB
        est = estimate_training_memory(K, 50, 2, 2)
        assert 0.95 * peak <= est <= 1.15 * peak, (K, peak / MIB, est / MIB)
