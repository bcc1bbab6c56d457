"""Commit the collocation solver's runs into docs/: every run directory's records under
docs/runs/suite-solve/EXPERIMENT/, and one summary of them all (suite.json, suite.md).

    make solve-runs     # runs/suite-solve: the hard suite and both long experiments, --profile solve
    python scripts/solve_doc.py runs/suite-solve docs/runs/suite-solve
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from atlasnn.report import suite_markdown, suite_summary

KEEP = ("results.json", "summary.json", "tables.csv", "meta.json", "config.toml")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, help="the folder holding EXPERIMENT/solve run directories")
    ap.add_argument("dest", type=Path, help="where the records and the summary go")
    args = ap.parse_args()
    dirs = sorted(p.parent for p in args.runs.glob("*/solve/results.json"))
    if not dirs:
        raise SystemExit(f"{args.runs}: no EXPERIMENT/solve/results.json in it; run `make solve-runs` first")
    for d in dirs:
        target = args.dest / d.parent.name
        target.mkdir(parents=True, exist_ok=True)
        for name in KEEP:
            if (d / name).is_file():
                shutil.copy2(d / name, target / name)
    summary = suite_summary(dirs)
    summary["suite"], summary["quick"] = "hard + long, collocation solver", False
    (args.dest / "suite.json").write_text(json.dumps(summary, indent=1, allow_nan=True) + "\n", encoding="utf-8")
    (args.dest / "suite.md").write_text(suite_markdown(summary), encoding="utf-8")
    print(suite_markdown(summary))


if __name__ == "__main__":
    main()
