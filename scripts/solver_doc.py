"""The measured tables of docs/SOLVER.md and docs/CHOOSING.md, made from the committed records.

Each table sits between ``<!-- solver-doc: NAME -->`` and ``<!-- /solver-doc -->`` in a page; this
script rewrites what is between them from the record it names (tests/solver/test_solver_doc.py checks that
the pages hold what it makes, so no number on them can drift from its record):

* ``suite``: docs/runs/solver/suite.json (``python -m benchmarks.solver_suite``);
* ``workprecision``: docs/benchmarks/solver_workprecision.json (``python -m benchmarks.solver_workprecision``);
* ``energy``: docs/benchmarks/energy_long.json (``python -m benchmarks.energy_long``);
* ``step_modes``: docs/benchmarks/step_modes.json (``python -m benchmarks.step_modes``);
* ``batch``: docs/benchmarks/solver_batch.json (``python -m benchmarks.solver_batch``);
* ``first_run``: docs/benchmarks/solver_first_run.json (``python -m benchmarks.solver_first_run``);
* ``stages``: docs/benchmarks/gauss_stages.json (``python -m benchmarks.gauss_stages``);
* ``roundoff``: docs/benchmarks/gauss_roundoff.json (``python -m benchmarks.gauss_roundoff``);
* ``orders``: docs/benchmarks/gauss_orders.json (``python -m benchmarks.gauss_orders``);
* ``scaling``: docs/benchmarks/gauss_scaling.json (``python -m benchmarks.gauss_scaling``).

    python scripts/solver_doc.py            # rewrite the tables in place
    python scripts/solver_doc.py --check    # exit 1 if a page is not what the records make
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "docs" / "SOLVER.md", ROOT / "docs" / "CHOOSING.md"]
RECORDS = {
    "suite": "docs/runs/solver/suite.json",
    "workprecision": "docs/benchmarks/solver_workprecision.json",
    "energy": "docs/benchmarks/energy_long.json",
    "step_modes": "docs/benchmarks/step_modes.json",
    "batch": "docs/benchmarks/solver_batch.json",
    "first_run": "docs/benchmarks/solver_first_run.json",
    "stages": "docs/benchmarks/gauss_stages.json",
    "roundoff": "docs/benchmarks/gauss_roundoff.json",
    "orders": "docs/benchmarks/gauss_orders.json",
    "scaling": "docs/benchmarks/gauss_scaling.json",
}
METHODS = [("gauss-adaptive", "Gauss, adaptive"), ("diffrax-dopri8", "Diffrax Dopri8"),
           ("diffrax-tsit5", "Diffrax Tsit5"), ("dop853", "SciPy DOP853"), ("yoshida4", "Yoshida-4"),
           ("collocation", "Collocation (random features)")]
_BLOCK = re.compile(r"(<!-- solver-doc: (\w+) -->\n)(.*?)(<!-- /solver-doc -->)", re.S)


def _load(name: str) -> dict | None:
    path = ROOT / RECORDS[name]
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def _ms(seconds: float) -> str:
    ms = seconds * 1e3
    return f"{ms:.3g} ms" if ms < 1000 else f"{seconds:.3g} s"


def suite(record: dict) -> str:
    rows = ["| problem | max error / range | reference (its gap) | estimate / true | windows | time (first call) | verdict |",
            "|---|---|---|---|---|---|---|"]
    for r in record["rows"]:
        if r["status"] != "ok":
            rows.append(f"| {r['problem']} | failed: {r['message'][:60]} | | | | | |")
            continue
        gap = "exact" if r["reference"] == "exact" else f"Gauss s = 16 ({r['reference_gap']:.0e})"
        right = "right" if r["verdict_right"] else "**wrong**"
        rows.append(f"| {r['problem']} | {r['error_rel']:.1e} | {gap} | {r['effectivity']:.2f} | {r['windows']} "
                    f"| {_ms(r['seconds'])} | {r['verdict']} ({right}) |")
    return "\n".join(rows)


def workprecision(record: dict) -> str:
    head = "| problem | Gauss (default) | " + " | ".join(label for _, label in METHODS) + " |"
    rows = [head, "|" + "---|" * (len(METHODS) + 2)]
    for name, prob in record["problems"].items():
        eq = prob["equal_accuracy"]
        g = eq["gauss_default"]
        cells = [f"{g['error_rel']:.1e} in {_ms(g['seconds'])}"]
        for method, _ in METHODS:
            pts = [r for r in prob["rows"] if r["method"] == method and "error_rel" in r]
            if not pts:
                cells.append("—")
            elif eq.get(method):
                m = eq[method]
                cells.append(f"{_ms(m['seconds'])} (×{m['ratio']:.2g})")
            else:
                best = min(pts, key=lambda r: r["error_rel"])
                cells.append(f"never; best {best['error_rel']:.0e} in {_ms(best['seconds'])}")
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def energy(record: dict) -> str:
    rows = ["| method | periods | max \\|H/H0 − 1\\| | growth t^a, last two decades | max \\|L − L0\\| | time |",
            "|---|---|---|---|---|---|"]
    for name, r in record["methods"].items():
        rows.append(f"| {name} | {r['periods']:.0e} | {r['energy_max_all']:.1e} | {r['growth_exponent']:.2f} | "
                    f"{r['momentum_max_all']:.0e} | {r['seconds']:.0f} s |")
    return "\n".join(rows)


def step_modes(record: dict) -> str:
    rows = ["| e | periods | rtol | lengths | windows | time | max \\|H/H0 − 1\\| | growth t^a |",
            "|---|---|---|---|---|---|---|---|"]
    for r in record["rows"]:
        rows.append(f"| {r['e']} | {r['periods']} | {r['rtol']:.0e} | {r['steps']} | {r['windows']} | "
                    f"{r['seconds']:.2g} s | {r['energy_max']:.1e} | {r['growth_exponent']:.2f} |")
    return "\n".join(rows)


def batch(record: dict) -> str:
    rows = ["| members | Gauss (solve_batch) | Diffrax Tsit5, vmap, rtol 1e-14 | Diffrax Dopri8, vmap, rtol 1e-14 |",
            "|---|---|---|---|"]
    for r in record["rows"]:
        cells = [f"{_ms(r['gauss_seconds'])}, {r['gauss_worst_error']:.0e}"]
        for label in ("tsit5", "dopri8"):
            key = f"{label}_1e-14"
            cells.append(f"{_ms(r[key + '_seconds'])}, {r[key + '_worst_error']:.0e}" if key + "_seconds" in r else "—")
        rows.append(f"| {r['members']} | " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n\nEach cell: the time for all members and their values at 100 times, then the worst member's error / range."


def first_run(record: dict) -> str:
    rows = ["| cache | import | first solve | of which its program's first call | second solve and evaluation |",
            "|---|---|---|---|---|"]
    for kind, runs in record["runs"].items():
        med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        rows.append(f"| {kind} | {med['import']:.2f} s | {med['first_solve']:.2f} s | {med['first_program_call']:.2f} s "
                    f"| {med['second_solve_and_evaluation'] * 1e3:.1f} ms |")
    return "\n".join(rows) + f"\n\nMedians of {len(next(iter(record['runs'].values())))} or more fresh processes each."


def stages(record: dict) -> str:
    counts = sorted({r["stages"] for r in record["rows"]})
    rows = ["| problem | rtol | " + " | ".join(f"s = {s}" for s in counts) + " |", "|---|---|" + "---|" * len(counts)]
    cases = sorted({(r["problem"], r["rtol"]) for r in record["rows"]}, key=lambda c: (c[0], -c[1]))
    for name, rtol in cases:
        got = {r["stages"]: r for r in record["rows"] if (r["problem"], r["rtol"]) == (name, rtol)}
        cells = [f"{_ms(got[s]['seconds'])}, {got[s]['error_rel']:.0e}" if s in got else "—" for s in counts]
        rows.append(f"| {name} | {rtol:.0e} | " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n\nEach cell: the whole call's time after compilation (best of 3), then its max error / range."


def roundoff(record: dict) -> str:
    rows = ["| e | periods | windows | estimate / range | true error / range | estimate / true | two tight solutions apart "
            "| h = shortest window: error (estimate) | h / 2: error (estimate) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in record["rows"]:
        given = [f"{r[k]['error_rel']:.1e} ({r[k]['estimate_rel']:.1e})" for k in ("given_h", "given_h_half")]
        rows.append(f"| {r['e']} | {r['periods']} | {r['windows']} | {r['estimate_rel']:.1e} | {r['error_rel']:.1e} | "
                    f"{r['estimate_over_error']:.2f} | {r['floor_rel']:.1e} | " + " | ".join(given) + " |")
    return "\n".join(rows)


def orders(record: dict) -> str:
    counts = sorted({r["stages"] for res in record["results"].values() for r in res["rows"]})
    rows = ["| problem | rtol | " + " | ".join(f"s = {s}" for s in counts) + " |", "|---|---|" + "---|" * len(counts)]
    for name, res in record["results"].items():
        for rtol in sorted({r["rtol"] for r in res["rows"]}, reverse=True):
            got = {r["stages"]: r for r in res["rows"] if r["rtol"] == rtol}
            best = (res["fastest_at_rtol"].get(f"{rtol:g}") or {}).get("stages")
            cells = []
            for s in counts:
                r = got.get(s)
                cell = "—" if r is None else "failed" if "seconds" not in r else f"{_ms(r['seconds'])}, {r['error_rel']:.0e}"
                cells.append(f"**{cell}**" if s == best else cell)
            rows.append(f"| {name} | {rtol:.0e} | " + " | ".join(cells) + " |")
    return "\n".join(rows) + ("\n\nEach cell: the whole call's time after compilation (best of 3), then its max error / range; "
                              "the fastest at each rtol in bold; — not run (order far below the tolerance's digits).")


def scaling(record: dict) -> str:
    rows = ["| system | d | s | windows | iterations / window | µs / window | of which the field's evaluations | "
            "first call |", "|---|---|---|---|---|---|---|---|"]
    for r in record["per_window"]:
        rows.append(f"| {r['kind']} | {r['d']} | {r['stages']} | {r['windows']} | {r['iterations_per_window']:.1f} | "
                    f"{r['us_per_window']:.3g} | {r['field_us'] * r['iterations_per_window']:.3g} | "
                    f"{r['first_call_seconds']:.2f} s |")
    out = "\n".join(rows)
    if record.get("fput"):
        rows = ["| FPUT-β, N | rtol | atlasnn: time, error (s, windows) | Diffrax Dopri8, fastest as accurate | "
                "Diffrax Tsit5, fastest as accurate |", "|---|---|---|---|---|"]
        for r in record["fput"]:
            cells = []
            for label in ("dopri8", "tsit5"):
                good = [p for p in r[label]["points"] if p["error"] <= 2 * r["atlasnn_error"]]
                f = min(good, key=lambda p: p["seconds"]) if good else None
                cells.append("none within 2× of its error" if f is None else
                             f"{_ms(f['seconds'])}, {f['error']:.0e} (rtol {f['rtol']:.0e}): "
                             f"atlasnn {r['atlasnn_seconds'] / f['seconds']:.2g}×")
            rows.append(f"| {r['n']} | {r['rtol']:.0e} | {_ms(r['atlasnn_seconds'])}, {r['atlasnn_error']:.0e} "
                        f"(s = {r['stages']}, {r['windows']}) | " + " | ".join(cells) + " |")
        out += "\n\n" + "\n".join(rows) + ("\n\nErrors: max over 200 times / range, against Diffrax Dopri8 at rtol "
                                           "1e-14 (at N ≤ 256 within 1e-14 of the Gauss method at s = 16); a Diffrax "
                                           "run counts as accurate as atlasnn's within 2× of its error (rtol 1e-6 … "
                                           "1e-13 swept); \"atlasnn k×\": atlasnn's time over that run's.")
    return out


MAKERS = {"suite": suite, "workprecision": workprecision, "energy": energy, "step_modes": step_modes, "batch": batch,
          "first_run": first_run, "stages": stages,
          "roundoff": roundoff, "orders": orders, "scaling": scaling}


def render(text: str) -> str:
    def one(match: re.Match) -> str:
        name = match.group(2)
        record = _load(name)
        if record is None:
            body = f"(no record yet: `{RECORDS[name]}`)\n"
        else:
            load = (record.get("machine") or {}).get("load_average")
            note = f" Load average {load[0]:.1f} while it ran." if load else ""
            body = f"{MAKERS[name](record)}\n\nMade by `{record['command'].strip()}` → `{RECORDS[name]}`.{note}\n"
        return match.group(1) + body + match.group(4)

    return _BLOCK.sub(one, text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if a page differs from what the records make")
    args = ap.parse_args(argv)
    stale = []
    for page in PAGES:
        if not page.is_file():
            continue
        text = page.read_text(encoding="utf-8")
        new = render(text)
        if new != text:
            stale.append(page)
            if not args.check:
                page.write_text(new, encoding="utf-8")
    if args.check and stale:
        print("out of date: " + ", ".join(str(p.relative_to(ROOT)) for p in stale) + "; run python scripts/solver_doc.py")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
