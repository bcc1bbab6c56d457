"""benchmarks.time_to_accuracy's summary: per seed the cheapest setting reaching each target."""

from __future__ import annotations

from benchmarks.time_to_accuracy import markdown, summarise


def _row(seed, rtol, epochs, seconds, error):
    return {"problem": "p", "seed": seed, "rtol": rtol, "adam_epochs": epochs, "training_seconds": seconds,
            "max_error": error}


def test_the_cheapest_setting_that_reaches_each_target_is_chosen_per_seed():
    rows = [_row(0, 1e-3, 500, 2.0, 5e-4), _row(0, 1e-4, 500, 5.0, 5e-5), _row(0, 1e-5, 2000, 9.0, 8e-6),
            _row(1, 1e-3, 500, 3.0, 2e-3), _row(1, 1e-4, 2000, 6.0, 9e-4), _row(1, 1e-5, 2000, 12.0, 2e-5)]
    classic = {"p": [{"method": "yoshida4", "setting": "N=100", "seconds": 1e-3, "max_error": 2e-4},
                     {"method": "dop853", "setting": "tol=1e-08", "seconds": 5e-3, "max_error": 1e-6}]}
    by_target = {s["target"]: s for s in summarise(rows, classic)}
    assert by_target[1e-3]["reached"] == 2 and by_target[1e-3]["median_seconds"] == 4.0  # 2.0 and 6.0
    assert by_target[1e-3]["settings"] == ["rtol 0.001, Adam 500", "rtol 0.0001, Adam 2000"]
    assert by_target[1e-5]["reached"] == 1 and by_target[1e-5]["settings"][1] is None
    assert by_target[1e-3]["classical"] == "yoshida4 N=100" and by_target[1e-5]["classical"] == "dop853 tol=1e-08"
    table = markdown(summarise(rows, classic))
    assert "| p | 1e-05 | 1 of 2 | 9.0 (9.0) |" in table
