"""Collect finished full-setting runs into docs/REPRODUCTION_RESULTS.md and docs/figures/.

    python scripts/reproduction_doc.py runs/oscillator-short runs/oscillator-transfer ...

For each run directory: the command and wall time (from meta.json), the tables atlasnn wrote
(tables.md), and the main figures copied into docs/figures/<experiment>/. Nothing here is typed
by hand: re-run the script after re-running the experiments.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

FIGURES = ["overview", "trajectories", "errors", "energy", "loss", "target_loss_comparison", "loss_source", "gamma",
           "seed_spread_l2_x"]


def section(run: Path, docs: Path) -> str:
    meta = json.loads((run / "meta.json").read_text())
    res = json.loads((run / "results.json").read_text())
    name = res["experiment"]
    fig_dir = docs / "figures" / name
    fig_dir.mkdir(parents=True, exist_ok=True)
    lines = [f"## {name}", ""]
    argv = meta.get("command", "").split()
    cmd = " ".join(["atlasnn"] + [a.replace(str(run.parent) + "/", "runs/") for a in argv[1:]])
    lines.append(f"Command: `{cmd}` — seeds {meta['seeds']}, jobs {meta['jobs']}, "
                 f"wall time {meta.get('wall_time_total', float('nan')) / 60:.1f} min on this machine "
                 f"(atlasnn {meta['versions']['atlasnn']}, JAX {meta['versions']['jax']}, {meta['versions']['backend']}).")
    lines.append("")
    tables = (run / "tables.md").read_text().replace("\n# ", "\n### ").replace("\n## ", "\n### ")
    if tables.startswith("# "):
        tables = "### " + tables[2:]
    lines += [tables.strip(), ""]
    for stem in FIGURES:
        src = run / "figures" / f"{stem}.png"
        if src.exists():
            shutil.copyfile(src, fig_dir / f"{stem}.png")
            lines.append(f"![{name} {stem}](figures/{name}/{stem}.png)")
    lines.append("")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--docs", type=Path, default=Path("docs"))
    args = ap.parse_args()
    parts = ["# Reproduction results (generated)", "",
             "Written by `scripts/reproduction_doc.py` from the run directories; the discussion is in "
             "[REPRODUCTION.md](REPRODUCTION.md).", ""]
    for run in args.runs:
        parts.append(section(run, args.docs))
    (args.docs / "REPRODUCTION_RESULTS.md").write_text("\n".join(parts), encoding="utf-8")
    print(f"wrote {args.docs / 'REPRODUCTION_RESULTS.md'}")


if __name__ == "__main__":
    main()
