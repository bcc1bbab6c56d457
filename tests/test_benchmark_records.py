"""The bookkeeping of benchmark records updated in parts (``--update``): a record names, for its
rows, the runs that made them, and no run none of whose rows it keeps."""

from __future__ import annotations

import jax
import pytest


@pytest.fixture(scope="module")
def earlier_runs():
    """The benchmark's bookkeeping, imported without leaving on the float64 switch its module
    turns on (the tests after this one in the worker run in JAX's default precision)."""
    was = jax.config.read("jax_enable_x64")
    from benchmarks.learned_h_regimes import earlier_runs

    jax.config.update("jax_enable_x64", was)
    return earlier_runs


def _rows(cells):
    return [{"system": name, "spacing": spacing} for name, spacing in cells]


def test_an_updated_record_names_only_the_runs_whose_rows_it_keeps(earlier_runs):
    rows = _rows([("pendulum", 0.1), ("pendulum", 0.5), ("pendulum", 1.0), ("two-body", 0.1)])
    # the pendulum at every spacing and two bodies by a first run; the pendulum at Δt 1 by a second
    kept = {"command": "second", "machine": None, "rows": rows,
            "updated": {"problems": ["pendulum at Δt 1"],
                        "earlier_runs": [{"problems": ["pendulum", "two-body"], "command": "first", "machine": None}]}}
    third = earlier_runs(kept, ["pendulum at Δt 0.5"], rows)
    assert [(run["command"], run["problems"]) for run in third] == [
        ("second", ["pendulum at Δt 1"]), ("first", ["pendulum", "two-body"])]  # the first still made Δt 0.1
    # a fourth run replaces the pendulum at Δt 0.1: the first run's pendulum rows are all gone
    record = {"command": "third", "machine": None, "rows": rows,
              "updated": {"problems": ["pendulum at Δt 0.5"], "earlier_runs": third}}
    fourth = earlier_runs(record, ["pendulum at Δt 0.1"], rows)
    assert [(run["command"], run["problems"]) for run in fourth] == [
        ("third", ["pendulum at Δt 0.5"]), ("second", ["pendulum at Δt 1"]), ("first", ["two-body"])]
    # the pendulum rerun whole: no earlier run made any of its rows
    assert [(run["command"], run["problems"]) for run in earlier_runs(record, ["pendulum"], rows)] == [
        ("first", ["two-body"])]
