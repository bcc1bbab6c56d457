"""Collect finished full-setting runs into the reproduction docs. Nothing here is typed by hand:
re-run the script after re-running the experiments.

    python scripts/reproduction_doc.py runs/paper/* runs/release/*

For each run directory (any profile):

- its small summaries go to ``docs/runs/PROFILE/EXPERIMENT/`` (results.json, summary.json,
  tables.csv, meta.json; no checkpoints or arrays);
- a section in docs/REPRODUCTION_RESULTS.md: command, wall time, the tables atlasnn wrote, and
  the main figures (copied to ``docs/figures/PROFILE/EXPERIMENT/``);

and over all of them:

- per transfer experiment, the loss–accuracy figure (final target loss against L2(x) for every
  model × seed × profile, the paper's run marked): ``docs/figures/EXPERIMENT/loss_vs_accuracy.png``;
- the generated parts of docs/REPRODUCTION.md, each between ``<!-- generated:NAME -->`` and
  ``<!-- /generated:NAME -->`` markers: ``headline`` (median [min–max] L2(x) per experiment, model
  and profile, the paper's value beside it), ``claims`` (how many seeds each of the paper's
  claims holds in, per profile; :mod:`atlasnn.report._claims`) and ``long`` (the long-time experiments:
  accuracy in every seed and the cost against classical integrators, from their work–precision
  records) and ``timing`` (the wall times ``scripts/timed.py`` recorded beside the runs, e.g.
  runs/paper/timing.json from ``make reproduce-all``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from atlasnn import AtlasError  # noqa: E402
from atlasnn.report import claims_markdown, experiment_claims, format_number, load_paper  # noqa: E402
from atlasnn.report import replace_generated as replace_marked  # noqa: E402

# the overview already shows trajectories, errors and energy; the run directory keeps the full set
FIGURES = ["overview", "loss", "target_loss_comparison", "loss_source", "gamma", "seed_spread_l2_x", "work_precision"]
SUMMARY_FILES = ["results.json", "summary.json", "tables.csv", "meta.json", "workprecision.json"]


def _profile(run: Path, res: dict) -> str:
    if res.get("profile"):
        return str(res["profile"])
    meta = json.loads((run / "meta.json").read_text())
    return str(meta.get("profile") or "paper")


def _command(run: Path, meta: dict) -> str:
    argv = meta.get("command", "").split()
    return " ".join(["atlasnn"] + [a.replace(str(run.parent) + "/", "runs/") for a in argv[1:]])


def _copy_figure(src: Path, dst: Path) -> None:
    """A PNG for the docs, reduced to a 128-colour palette (about a quarter of the bytes; the line
    plots lose nothing visible), so that the repository does not grow by tens of MB per rerun."""
    from PIL import Image

    with Image.open(src) as im:
        im.convert("RGB").quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)


def section(run: Path, docs: Path) -> str:
    meta = json.loads((run / "meta.json").read_text())
    res = json.loads((run / "results.json").read_text())
    name, profile = res["experiment"], _profile(run, res)
    keep = docs / "runs" / profile / name
    keep.mkdir(parents=True, exist_ok=True)
    for f in SUMMARY_FILES:
        if (run / f).exists():
            shutil.copyfile(run / f, keep / f)
    fig_dir = docs / "figures" / profile / name
    fig_dir.mkdir(parents=True, exist_ok=True)
    lines = [f"## {name} — profile {profile}", ""]
    lines.append(f"Command: `{_command(run, meta)}` — seeds {meta['seeds']}, jobs {meta['jobs']}, "
                 f"wall time {meta.get('wall_time_total', float('nan')) / 60:.1f} min on this machine "
                 f"(atlasnn {meta['versions']['atlasnn']}, JAX {meta['versions']['jax']}, {meta['versions']['backend']}). "
                 f"Summaries: [docs/runs/{profile}/{name}/summary.json](runs/{profile}/{name}/summary.json).")
    lines.append("")
    tables = (run / "tables.md").read_text().replace("\n# ", "\n### ").replace("\n## ", "\n### ")
    if tables.startswith("# "):
        tables = "### " + tables[2:]
    lines += [tables.strip(), ""]
    for stem in FIGURES:
        src = run / "figures" / f"{stem}.png"
        if src.exists():
            _copy_figure(src, fig_dir / f"{stem}.png")
            lines.append(f"![{name} {profile} {stem}](figures/{profile}/{name}/{stem}.png)")
    lines.append("")
    return "\n".join(lines)


def headline(runs: dict[str, dict[str, dict]]) -> str:
    """Median [min–max] L2 of the first state per model, per experiment and profile."""
    out = ["| experiment | profile | seeds | " + "model: median [min–max] (paper) |" , "|---|---|---|---|"]
    for name, by_profile in runs.items():
        for profile, res in by_profile.items():
            try:
                paper = load_paper(res.get("paper_experiment") or name)["rows"]
            except Exception:
                paper = {}
            state = res["state_names"][0]
            cells = []
            for column in res["columns"]:
                vals = sorted(r["metrics"]["l2_discrete"][state] for r in res["runs"]
                              if r["column"] == column and r.get("role", "short") in ("short", "target", "march"))
                if column == "se":
                    se = next((i for i in res.get("integrators") or [] if i["column"] == "se"), None)
                    vals = [se["metrics"]["l2_discrete"][state]] if se else []
                if not vals:
                    continue
                med = vals[len(vals) // 2] if len(vals) % 2 else (vals[len(vals) // 2 - 1] + vals[len(vals) // 2]) / 2
                text = format_number(med) if len(vals) == 1 else \
                    f"{format_number(med)} [{format_number(vals[0])}–{format_number(vals[-1])}]"
                p = paper.get(f"l2_{state}", {}).get(column)
                label = res.get("labels", {}).get(column, column)
                cells.append(f"{label}: {text}" + (f" ({format_number(p)})" if isinstance(p, (int, float)) else ""))
            out.append(f"| {name} | {profile} | {len(res['seeds'])} | " + "; ".join(cells) + " |")
    return "\n".join(out)


def _median(vals: list[float]) -> float:
    vals = sorted(vals)
    n = len(vals)
    return vals[n // 2] if n % 2 else (vals[n // 2 - 1] + vals[n // 2]) / 2


def long_time(runs: dict[str, dict[str, dict]]) -> str:
    """Per long-time experiment (one with a work–precision record): each network column's L2 of
    the first state and max error over seeds (median and worst), worst energy drift, training
    seconds per seed, and the cheapest classical setting as accurate as its *worst* seed."""
    from atlasnn.evaluation import SYMPLECTIC, WorkPoint, workprecision

    out = []
    for name, by_profile in runs.items():
        for profile, res in by_profile.items():
            wp = res.get("work_precision")
            if not wp:
                continue
            points = [WorkPoint(**p) for p in wp["points"]]
            state = wp["first_state"]
            out += [f"**{name}** (profile {profile}, {len(res['seeds'])} seeds, {wp['grid_points']} evaluation points)", "",
                    f"| model | L2({state}) median [worst] | max abs error median [worst] | energy drift, worst | "
                    "training s/seed, median | evaluate 10⁴ times | cheapest classical as accurate as the worst seed |",
                    "|---|---|---|---|---|---|---|"]
            for label in dict.fromkeys(p.method for p in points if p.kind == "network"):
                mine = [p for p in points if p.method == label]
                worst = max(mine, key=lambda p: p.max_error)
                match = workprecision.cheapest_match(points, worst)
                cheap = "none measured" if match is None else (
                    f"{SYMPLECTIC.get(match.method, 'DOP853')} {match.setting}: {format_number(match.max_error)} "
                    f"in {match.seconds:.3g} s ({worst.seconds / max(match.seconds, 1e-12):.3g}x cheaper)")
                ev = (wp.get("evaluation_seconds_1e4") or {}).get(label)
                out.append(f"| {label} | {format_number(_median([p.l2_first for p in mine]))} "
                           f"[{format_number(max(p.l2_first for p in mine))}] | "
                           f"{format_number(_median([p.max_error for p in mine]))} [{format_number(worst.max_error)}] | "
                           f"{format_number(max(p.energy_drift for p in mine))} | "
                           f"{_median([p.seconds for p in mine]):.3g} | "
                           f"{'' if ev is None else f'{ev * 1e3:.3g} ms'} | {cheap} |")
            out.append("")
    return "\n".join(out) or "(no long-time run given)"


def timing(run_dirs: list[Path], docs: Path) -> str:
    """The wall time of each batch of runs that ``scripts/timed.py`` recorded (a ``timing.json``
    beside the run directories, e.g. runs/paper/timing.json from ``make reproduce-all``); the
    record is copied to docs/runs/PROFILE/."""
    out = ["| record | command | wall time |", "|---|---|---|"]
    for parent in dict.fromkeys(run.parent for run in run_dirs):
        for record in sorted(parent.glob("*timing.json")):
            data = json.loads(record.read_text())
            keep = docs / "runs" / parent.name / record.name
            keep.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(record, keep)
            link = f"[{parent.name}/{record.name}](runs/{parent.name}/{record.name})"
            for c in data["commands"]:
                cmd = c["command"].replace(".venv/bin/", "")
                state = "" if c["status"] == 0 else f" (exit {c['status']})"
                out.append(f"| {link} | `{cmd}` | {c['seconds'] / 60:.1f} min{state} |")
            load = ", ".join(f"{x:.1f}" for x in data.get("load_before", [])[:1] + data.get("load_after", [])[:1])
            out.append(f"| {link} | **total** ({data.get('cpu_count')} cores; 1-min load before, after: {load}) | "
                       f"**{data['total_seconds'] / 60:.1f} min** |")
    return "\n".join(out) if len(out) > 2 else "(no timing record found beside the runs)"


def replace_generated(text: str, name: str, body: str) -> str:
    try:
        return replace_marked(text, name, body, "docs/REPRODUCTION.md")
    except AtlasError as exc:
        raise SystemExit(str(exc)) from None


def update_long(runs: list[Path], docs: Path) -> None:
    """Rewrite only what the long-time runs make: their sections of REPRODUCTION_RESULTS.md (in
    place) and the ``long`` section of REPRODUCTION.md."""
    results_page = docs / "REPRODUCTION_RESULTS.md"
    text = results_page.read_text(encoding="utf-8")
    by_exp: dict[str, dict[str, dict]] = {}
    for run in runs:
        res = json.loads((run / "results.json").read_text())
        if not res.get("work_precision"):
            raise SystemExit(f"{run}: not a long-time run (no work-precision record); drop --long-only")
        new = section(run, docs)
        head = new.splitlines()[0]
        start = text.find(head + "\n")
        if start < 0:
            text = text.rstrip("\n") + "\n\n" + new
        else:
            end = text.find("\n## ", start + len(head))
            text = text[:start] + new.rstrip("\n") + "\n" + (text[end:] if end >= 0 else "")
        by_exp.setdefault(res["experiment"], {})[_profile(run, res)] = res
    results_page.write_text(text, encoding="utf-8")
    doc = docs / "REPRODUCTION.md"
    text = replace_generated(doc.read_text(encoding="utf-8"), "long", long_time(by_exp))
    for row in headline(by_exp).splitlines()[2:]:  # the long experiments' rows of the headline table
        start = row[: row.index("|", row.index("|", 1) + 1) + 1]  # "| name | profile |"
        lines = text.splitlines()
        hits = [i for i, line in enumerate(lines) if line.startswith(start)]
        if len(hits) != 1:
            raise SystemExit(f"{doc}: expected one headline row starting {start!r}, found {len(hits)}")
        lines[hits[0]] = row
        text = "\n".join(lines) + "\n"
    doc.write_text(text, encoding="utf-8")
    print(f"updated the long-time sections of {results_page} and {doc} (and their headline rows)")


def estimate_table(runs: list[Path], docs: Path) -> str:
    """The error estimate and the verdict on the paper's experiments: per experiment and column,
    the true max error / range (worst, median), the estimate's worst, its effectivity range, the
    verdicts, and the verdict's false ok (> 5 % of the range) and false alarms (< 1e-3). Runs that
    are not long-time ones are copied to docs/runs/estimate/EXPERIMENT/ (results.json, meta.json)."""
    from atlasnn.report import suite_summary

    for run in runs:
        res = json.loads((run / "results.json").read_text())
        if not res.get("work_precision"):
            dest = docs / "runs" / "estimate" / res["experiment"]
            dest.mkdir(parents=True, exist_ok=True)
            for name in ("results.json", "meta.json"):
                shutil.copyfile(run / name, dest / name)
    summary = suite_summary(runs)
    rows = ["| experiment | model | worst max err/range | median | estimate, worst | effectivity | verdicts "
            "| false ok / false alarm |", "|---|---|---|---|---|---|---|---|"]
    effs: list[float] = []
    for p in summary["problems"]:
        for r in p["rows"]:
            eff = [e for e, t in zip(r["effectivity"], r["relative_max"]) if e is not None and t is not None and t > 1e-5]
            effs += eff
            span = f"{_ratio(min(eff))}–{_ratio(max(eff))}" if eff else "n/a"
            verdicts = ", ".join(f"{k} {v}" for k, v in r["verdicts"].items())
            rows.append(f"| {p['experiment']} | {r['label']} | {_num(r['worst'])} | {_num(r['median'])} | "
                        f"{_num(r['estimate_worst'])} | {span} | {verdicts} | {r['false_ok']} / {r['false_alarm']} |")
    t = summary["totals"]
    rows += ["", f"{t['trainings']} trainings; judged ok with a true error above 5 % of the range: {t['false_ok']}; "
             f"judged suspect or failed with one below 1e-3: {t['false_alarm']}; effectivity where the true error "
             f"exceeds 1e-5 of the range: {min(effs):.3g}–{max(effs):.3g}." if effs else ""]
    return "\n".join(rows)


def _ratio(v: float) -> str:
    """An effectivity: two decimals near 1, a power of ten where the estimate is only a flag."""
    return f"{v:.2f}" if 1e-2 <= v < 100 else f"{v:.1e}"


def _num(v) -> str:
    return "n/a" if v is None else format_number(v)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--docs", type=Path, default=Path("docs"))
    ap.add_argument("--long-only", action="store_true", help="the runs given are the long-time experiments: "
                    "replace their sections of REPRODUCTION_RESULTS.md and the long-time section of "
                    "REPRODUCTION.md, nothing else")
    ap.add_argument("--estimate-only", action="store_true", help="write only the estimate section of "
                    "REPRODUCTION.md (the error estimate and the verdict against the true error) from the runs given")
    args = ap.parse_args()
    args.runs = [r for r in args.runs if (r / "results.json").is_file()]  # `runs/paper/*` also matches timing.json
    if not args.runs:
        raise SystemExit("no run directory with a results.json among the paths given")
    if args.long_only:
        return update_long(args.runs, args.docs)
    if args.estimate_only:
        doc = args.docs / "REPRODUCTION.md"
        doc.write_text(replace_generated(doc.read_text(encoding="utf-8"), "estimate",
                                         estimate_table(args.runs, args.docs)), encoding="utf-8")
        return print(f"updated the estimate section of {doc}")
    by_exp: dict[str, dict[str, dict]] = {}
    dirs: dict[str, list[Path]] = {}
    parts = ["# Reproduction results (generated)", "",
             "Written by `scripts/reproduction_doc.py` from the run directories; the discussion is in "
             "[REPRODUCTION.md](REPRODUCTION.md).", ""]
    for run in args.runs:
        res = json.loads((run / "results.json").read_text())
        parts.append(section(run, args.docs))
        by_exp.setdefault(res["experiment"], {})[_profile(run, res)] = res
        dirs.setdefault(res["experiment"], []).append(run)
    (args.docs / "REPRODUCTION_RESULTS.md").write_text("\n".join(parts), encoding="utf-8")
    print(f"wrote {args.docs / 'REPRODUCTION_RESULTS.md'}")

    import loss_accuracy

    for name, runs in dirs.items():
        if by_exp[name][next(iter(by_exp[name]))]["kind"] != "transfer":
            continue
        stem = args.docs / "figures" / name / "loss_vs_accuracy"
        stem.parent.mkdir(parents=True, exist_ok=True)
        loss_accuracy.main([*map(str, runs), "--out", str(stem)])

    profiles = sorted({p for v in by_exp.values() for p in v}, key=lambda p: (p != "paper", p))
    claims = [experiment_claims(v) for v in by_exp.values()]
    doc = args.docs / "REPRODUCTION.md"
    text = doc.read_text(encoding="utf-8")
    text = replace_generated(text, "headline", headline(by_exp))
    text = replace_generated(text, "claims", claims_markdown(claims, profiles))
    text = replace_generated(text, "long", long_time(by_exp))
    text = replace_generated(text, "timing", timing(args.runs, args.docs))
    doc.write_text(text, encoding="utf-8")
    print(f"updated the generated sections of {doc}")


if __name__ == "__main__":
    main()
