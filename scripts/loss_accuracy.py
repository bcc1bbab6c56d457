"""Final training loss against accuracy over several run directories (one figure).

    python scripts/loss_accuracy.py runs/hh-transfer-paper runs/hh-transfer-release \
        --out docs/figures/henon-heiles-transfer/loss_vs_accuracy

Every training of every run directory becomes one point: x = the training loss of the parameters
that were returned and evaluated (``returned_loss`` in results.json; ``final_loss`` for older
runs), y = L2 of one state component in the release's form (the form of the paper's tables).
Source trainings of transfer runs are left out (their error is not measured on the target
interval). Each run's profile is read from its results.json or meta.json (``"profile"``); a run
without one predates profiles and used the paper-faithful settings, so it is called "paper";
``--profile DIR=NAME`` overrides. The paper's single run per model is marked at its L2 and, where
the authors' release logged it, at its final loss (docs/METHOD.md, "What the authors' release
did"); otherwise by a horizontal line. All run directories must compare with the same paper
experiment.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from atlasnn.report import QUICK_TAG
from atlasnn import AtlasError
from atlasnn.report import plot_loss_vs_accuracy
from atlasnn.report import load_paper, load_results

#: Final training losses of the paper's runs, read from the authors' release (its loss logs and
#: the physics loss of its shipped weights), per experiment and table column. The oscillator
#: transfer's and Hénon–Heiles short's were not recorded, so those get a horizontal line.
RELEASE_LOSSES = {
    "oscillator-short": {"hnn": 5e-6, "atlas_tanh": 7e-7, "atlas_exp": 2e-6},
    "henon-heiles-transfer": {"hnn_baseline": 1.5e-4, "hnn_transfer": 4.3e-5, "atlas_tanh_transfer": 1.75e-5,
                              "atlas_exp_transfer": 1.2e-7},
}


def _profile(run_dir: Path, results: dict, overrides: dict[str, str]) -> str:
    for key in (str(run_dir), str(run_dir.resolve()), run_dir.name):
        if key in overrides:
            return overrides[key]
    if results.get("profile"):
        return str(results["profile"])
    meta = run_dir / "meta.json"
    if meta.exists():
        profile = json.loads(meta.read_text(encoding="utf-8")).get("profile")
        if profile:
            return str(profile)
    return "paper"


def collect_points(run_dirs: list[Path], state: str = "x", overrides: dict[str, str] | None = None):
    """Points (model, profile, seed, loss, l2) of every table training, the paper experiment's
    name, and whether any of the runs was a quick run."""
    points, papers, quick = [], set(), False
    for run_dir in run_dirs:
        res = load_results(run_dir)
        if state not in res.get("state_names", []):
            raise AtlasError(f"{run_dir}: no state {state!r} (states: {res.get('state_names')})")
        papers.add(res.get("paper_experiment") or res["experiment"])
        quick = quick or bool(res.get("quick"))
        profile = _profile(Path(run_dir), res, overrides or {})
        for r in res.get("runs", []):
            if r.get("role") == "source":
                continue
            loss = r.get("returned_loss", r.get("final_loss"))
            l2 = (r.get("metrics") or {}).get("l2_discrete", {}).get(state)
            if loss is None or l2 is None:
                continue
            points.append({"model": res["labels"].get(r["column"], r["column"]), "column": r["column"],
                           "profile": profile, "seed": r.get("seed"), "loss": loss, "l2": l2})
    if len(papers) != 1:
        raise AtlasError(f"the runs compare with different experiments {sorted(papers)}; give runs of one experiment")
    return points, papers.pop(), quick


def paper_points(experiment: str, labels: dict[str, str], state: str = "x") -> dict[str, dict]:
    """{model label: {"l2", "loss"}} of the paper's runs (loss None where it was not logged)."""
    try:
        rows = load_paper(experiment)["rows"].get(f"l2_{state}", {})
    except AtlasError:
        return {}
    losses = RELEASE_LOSSES.get(experiment, {})
    return {labels[c]: {"l2": v, "loss": losses.get(c)} for c, v in rows.items()
            if c in labels and c != "se" and isinstance(v, (int, float))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="run directories (results.json in each)")
    ap.add_argument("--out", type=Path, required=True, help="figure stem: writes STEM.png and STEM.pdf")
    ap.add_argument("--state", default="x", help="the state component of the L2 (default x)")
    ap.add_argument("--profile", action="append", default=[], metavar="DIR=NAME",
                    help="the profile of a run directory, when its results.json does not say")
    args = ap.parse_args(argv)
    try:
        overrides = dict(p.split("=", 1) for p in args.profile)
    except ValueError:
        print(f"error: --profile takes DIR=NAME, got {args.profile}", file=sys.stderr)
        return 2
    try:
        points, experiment, quick = collect_points(args.runs, args.state, overrides)
        labels = {p["column"]: p["model"] for p in points}
        names = sorted({load_results(r)["experiment"] for r in args.runs} - {experiment})
        shown = f"{', '.join(names)} (the paper's {experiment})" if names else experiment
        title = f"{shown}: final training loss against L2({args.state})"
        paths = plot_loss_vs_accuracy(args.out, points, paper_points(experiment, labels, args.state),
                                      ylabel=f"L2({args.state}), release form (the paper's tables)",
                                      title=f"{QUICK_TAG}\n{title}" if quick else title)
    except AtlasError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
