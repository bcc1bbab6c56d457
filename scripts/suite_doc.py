"""Commit a suite run into docs/: the runs' records under docs/runs/suite/, the summary's tables
into docs/SUITE.md (between its ``<!-- generated:NAME -->`` markers), and each problem's overview
figure under docs/figures/suite/.

    python scripts/suite_doc.py runs/suite-hard --times   # after `make suite`, on a quiet machine
    python scripts/suite_doc.py docs/runs/suite --render-only   # the page's tables again from the record

Sections written: ``suite`` (a table per problem and scheme, from suite.json), ``targets`` (the
issue's targets counted: worst seed ≤ 1e-3 and median ≤ 1e-4 of the range for adaptive
time-marching; the verdict's false ok / false alarms; the estimate's effectivity where the true
error exceeds 1e-5 of the range) and ``timing`` (the suite's wall time, when timed.py recorded it).

The training seconds per seed and the suite's wall time are written only with ``--times``: pass it
when the run's timings describe the code as it is (a quiet machine, the current executors); without
it the page carries no timing and the tables no seconds column.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from atlasnn import AtlasError
from atlasnn.report import replace_generated as replace_marked
from atlasnn.report import suite_markdown

KEEP = ("results.json", "summary.json", "tables.csv", "meta.json", "config.toml")


def replace_generated(text: str, name: str, body: str) -> str:
    try:
        return replace_marked(text, name, body, "docs/SUITE.md")
    except AtlasError as exc:
        raise SystemExit(str(exc)) from None


def targets(summary: dict) -> str:
    rows = ["| problem | adaptive march: worst seed ≤ 1e-3 | median ≤ 1e-4 | effectivity in [1/3, 3] (counted) "
            "| outside it with a true error ≤ 5 % | verdicts: false ok / false alarm (all schemes) |",
            "|---|---|---|---|---|---|"]
    all_eff, counted = [], 0
    for p in summary["problems"]:
        adaptive = [r for r in p["rows"] if r["scheme"] == "time-marching, adaptive windows"]
        eff = [(e, t) for r in p["rows"] for e, t in zip(r["effectivity"], r["relative_max"])
               if e is not None and t is not None and t > 1e-5]
        inside = sum(1 / 3 <= e <= 3 for e, _ in eff)
        unexplained = sum(not 1 / 3 <= e <= 3 and t <= 0.05 for e, t in eff)  # linearisation still valid
        all_eff += [e for e, _ in eff]
        counted += len(eff)
        false_ok = sum(r["false_ok"] for r in p["rows"])
        false_alarm = sum(r["false_alarm"] for r in p["rows"])
        if adaptive:
            r = adaptive[0]
            worst = "yes" if r["worst"] is not None and r["worst"] <= 1e-3 else f"no ({r['worst']:.2g})"
            failed = [e for e, t in zip(r["estimate"], r["relative_max"]) if t is not None and t > 1e-3]
            if worst != "yes" and r["verdicts"].get("failed", 0) == len(r["seeds"]) and all(
                    e is not None and e > 0.05 for e in failed):
                worst += "; each of those seeds failed by its estimate"
            median = "yes" if r["median"] is not None and r["median"] <= 1e-4 else f"no ({r['median']:.2g})"
        else:
            worst = median = "not run"
        rows.append(f"| {p['experiment']} | {worst} | {median} | {inside} of {len(eff)} | {unexplained} "
                    f"| {false_ok} / {false_alarm} |")
    if all_eff:
        rows.append("")
        rows.append(f"Effectivity over the {counted} trainings whose true error exceeds 1e-5 of the range: "
                    f"{min(all_eff):.3g} – {max(all_eff):.3g}.")
    return "\n".join(rows)


def timing(suite_dir: Path, docs: Path) -> str:
    """Every timing record beside the suite directory (``NAME.timing*.json``: a suite stopped and
    run again leaves one per invocation), each command with its wall time and exit status."""
    records = sorted(suite_dir.parent.glob(f"{suite_dir.name}.timing*.json"),
                     key=lambda p: json.loads(p.read_text()).get("finished", ""))
    if not records:
        return "(no timing record beside the suite directory)"
    lines, total = [], 0.0
    for record in records:
        data = json.loads(record.read_text())
        shutil.copyfile(record, docs / "runs" / "suite" / record.name)
        for c in data["commands"]:
            total += c["seconds"]
            lines.append(f"`{c['command']}`: {c['seconds'] / 60:.1f} min (exit {c['status']}, finished "
                         f"{data.get('finished', '?')}; [runs/suite/{record.name}](runs/suite/{record.name}))")
    return "\n\n".join(lines) + f"\n\nIn all {total / 60:.1f} min on {data.get('cpu_count')} cores."


def drop_column(markdown: str, header: str) -> str:
    """The Markdown tables of ``markdown`` without their column named ``header``."""
    out, index = [], None
    for line in markdown.splitlines():
        cells = line.strip().strip("|").split("|") if line.startswith("|") else None
        if cells is None:
            index = None
        elif header in [c.strip() for c in cells]:
            index = [c.strip() for c in cells].index(header)
        if cells is not None and index is not None:
            line = "|" + "|".join(cells[:index] + cells[index + 1:]) + "|"
        out.append(line)
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite", type=Path, help="the suite directory (holds suite.json)")
    ap.add_argument("--docs", type=Path, default=Path("docs"))
    ap.add_argument("--times", action="store_true", help="also the training seconds and the wall time")
    ap.add_argument("--render-only", action="store_true",
                    help="rewrite the page's tables from SUITE/suite.json, copying nothing")
    args = ap.parse_args()
    summary = json.loads((args.suite / "suite.json").read_text())
    dest = args.docs / "runs" / "suite"
    for run in [] if args.render_only else sorted(p.parent for p in args.suite.glob("*/*/results.json")):
        out = dest / run.parent.name / run.name
        out.mkdir(parents=True, exist_ok=True)
        for name in KEEP:
            if (run / name).is_file():
                shutil.copyfile(run / name, out / name)
        fig = run / "figures" / "overview.png"
        if fig.is_file():
            figs = args.docs / "figures" / "suite" / run.parent.name
            figs.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(fig, figs / f"overview-{run.name}.png")
    if not args.render_only:
        shutil.copyfile(args.suite / "suite.json", dest / "suite.json")
    page = args.docs / "SUITE.md"
    text = page.read_text(encoding="utf-8")
    tables = suite_markdown(summary)
    text = replace_generated(text, "suite", tables if args.times else drop_column(tables, "training s/seed"))
    text = replace_generated(text, "targets", targets(summary))
    if args.times and "<!-- generated:timing -->" in text:
        text = replace_generated(text, "timing", timing(args.suite, args.docs))
    page.write_text(text, encoding="utf-8")
    print(f"wrote {page} and {dest}")


if __name__ == "__main__":
    main()
