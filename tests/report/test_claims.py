"""The paper's claims counted seed by seed (atlasnn.report._claims), on hand-made results."""

from __future__ import annotations

from atlasnn.report._claims import experiment_claims, markdown


def _run(column, seed, l2, epochs=100, role="short"):
    return {"column": column, "seed": seed, "role": role, "epochs": epochs,
            "metrics": {"l2_discrete": {"x": l2, "p": 1.0}}}


def _results(values: dict[str, list[float]], se: float, kind="short", epochs=None):
    role = "short" if kind == "short" else "target"
    runs = [_run(c, s, v, (epochs or {}).get(c, [100] * len(vs))[s], role)
            for c, vs in values.items() for s, v in enumerate(vs)]
    return {"experiment": "oscillator-short" if kind == "short" else "oscillator-transfer", "kind": kind,
            "state_names": ["x", "p"], "columns": ["se", *values], "baseline": next(iter(values)),
            "labels": {c: c.upper() for c in values}, "runs": runs, "seeds": [0, 1, 2],
            "integrators": [{"column": "se", "metrics": {"l2_discrete": {"x": se}}}]}


def test_claims_of_the_short_oscillator_counted_per_seed_and_profile():
    # paper (oscillator-short): HNN 1.17e-2, ATLAS tanh 1.12e-2, ATLAS exp 4.31e-3, SE 1.43
    paper_profile = _results({"hnn": [5e-3, 5e-3, 5e-3], "atlas_tanh": [4e-3, 6e-3, 7e-3],
                              "atlas_exp": [3e-3, 9e-3, 2.0]}, se=1.43)
    release = _results({"hnn": [5e-3, 5e-3, 5e-3], "atlas_tanh": [1e-3, 1e-3, 1e-3],
                        "atlas_exp": [4e-3, 4e-3, 4e-3]}, se=1.43)
    out = experiment_claims({"paper": paper_profile, "release": release})
    rows = {r["claim"]: r for r in out["rows"]}
    beat = rows["ATLAS_EXP better than HNN (L2(x))"]
    assert beat["paper"] is True and beat["profiles"] == {"paper": {"k": 1, "n": 3}, "release": {"k": 3, "n": 3}}
    assert rows["ATLAS_EXP better than SE (L2(x))"]["profiles"]["paper"] == {"k": 2, "n": 3}
    reach = rows["ATLAS_EXP reaches the paper's L2(x) = 0.00431"]
    assert reach["paper"] is None and reach["profiles"]["paper"] == {"k": 1, "n": 3}
    assert reach["profiles"]["release"] == {"k": 3, "n": 3}
    text = markdown([out], ["paper", "release"])
    assert "| ATLAS_EXP better than HNN (L2(x)) | 0.00431 vs 0.0117 | 1/3 | 3/3 |" in text


def test_a_claim_the_paper_makes_negatively_counts_the_agreeing_seeds():
    # oscillator transfer: the paper's HNN transfer (0.224) beats its baseline (0.668), and its
    # epochs row: HNN transfer 19818 vs baseline 20191 (fewer)
    values = {"hnn_baseline": [0.3, 0.3, 0.3], "hnn_transfer": [0.2, 0.5, 0.6],
              "atlas_tanh_transfer": [1, 1, 1], "atlas_exp_transfer": [1, 1, 1]}
    epochs = {"hnn_baseline": [100, 100, 100], "hnn_transfer": [90, 120, 80],
              "atlas_tanh_transfer": [1, 1, 1], "atlas_exp_transfer": [1, 1, 1]}
    out = experiment_claims({"paper": _results(values, se=27.2, kind="transfer", epochs=epochs)})
    rows = {r["claim"]: r for r in out["rows"]}
    assert rows["HNN_TRANSFER better than HNN_BASELINE (L2(x))"]["profiles"]["paper"] == {"k": 1, "n": 3}
    assert rows["HNN_TRANSFER needs fewer target epochs than HNN_BASELINE"]["profiles"]["paper"] == {"k": 2, "n": 3}
    # Hénon–Heiles transfer: the paper's ATLAS tanh (13.7) is worse than its baseline (13.5)
    hh = _results({"hnn_baseline": [10, 10, 10], "hnn_transfer": [9, 9, 9],
                   "atlas_tanh_transfer": [12, 8, 11], "atlas_exp_transfer": [1, 1, 1]}, se=1.67, kind="transfer")
    hh["experiment"], hh["state_names"] = "henon-heiles-transfer", ["x", "y", "px", "py"]
    rows = {r["claim"]: r for r in experiment_claims({"paper": hh})["rows"]}
    worse = rows["ATLAS_TANH_TRANSFER not better than HNN_BASELINE (L2(x))"]
    assert worse["paper"] is False and worse["profiles"]["paper"] == {"k": 2, "n": 3}


def test_a_long_experiment_is_checked_against_its_paper_table_under_its_own_name():
    res = _results({"hnn_baseline": [0.5, 0.6], "atlas_exp_transfer": [0.05, 0.9]}, se=27.2, kind="transfer")
    res["experiment"], res["paper_experiment"] = "oscillator-long", res["experiment"]
    out = experiment_claims({"paper": res})
    assert out["experiment"] == "oscillator-long" and out["paper_experiment"] == res["paper_experiment"]
    rows = {r["claim"]: r for r in out["rows"]}  # the paper's oscillator-transfer numbers are used
    assert rows["ATLAS_EXP_TRANSFER reaches the paper's L2(x) = 0.0973"]["profiles"]["paper"] == {"k": 1, "n": 2}
    text = markdown([out], ["paper", "release"])
    assert f"against the paper's {res['paper_experiment']}" in text
    assert "release profile" not in text  # only the profiles the experiment was run in get a column
