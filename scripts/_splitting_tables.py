"""The measured tables of docs/SPLITTING_MEASURED.md (made by ``scripts/solver_doc.py``, which owns the
blocks, the pages and the check): ``splitting`` from docs/benchmarks/splitting_workprecision.json
(``python -m benchmarks.splitting_workprecision``), ``splitting_nls`` from
docs/benchmarks/splitting_nls.json (``python -m benchmarks.splitting_nls``), ``splitting_long`` from
docs/benchmarks/splitting_long.json (``python -m benchmarks.splitting_long``), ``splitting_solar``
from docs/benchmarks/splitting_solar.json (``python -m benchmarks.splitting_solar``), ``splitting_breakdown``
from docs/benchmarks/splitting_breakdown.json (``python -m benchmarks.splitting_breakdown``), ``rival_costs``
from docs/benchmarks/rival_costs.json (``python -m benchmarks.rival_costs``)."""

from __future__ import annotations

from _doc_format import milliseconds as _ms

RECORDS = {"splitting": "docs/benchmarks/splitting_workprecision.json",
           "splitting_nls": "docs/benchmarks/splitting_nls.json",
           "splitting_long": "docs/benchmarks/splitting_long.json",
           "splitting_solar": "docs/benchmarks/splitting_solar.json",
           "splitting_breakdown": "docs/benchmarks/splitting_breakdown.json",
           "rival_costs": "docs/benchmarks/rival_costs.json"}

_COLUMNS = (("gauss", "GaussCollocation"), ("diffrax-dopri8", "Diffrax Dopri8"), ("diffrax-tsit5", "Diffrax Tsit5"))


def _cell(fastest: dict, method: str) -> str:
    hit = fastest.get(method)
    return "never" if hit is None else _ms(hit[0])


def _best_splitting(fastest: dict) -> str:
    runs = [(s, m.removeprefix("splitting-")) for m, (s, _) in fastest.items() if m.startswith("splitting-")]
    if not runs:
        return "—"
    seconds, scheme = min(runs)
    return f"{_ms(seconds)} ({scheme})"


def splitting(record: dict) -> str:
    rows = ["| problem | error / range ≤ | `solve` (default) | best fixed scheme | "
            + " | ".join(label for _, label in _COLUMNS) + " | default / fastest Diffrax |",
            "|---|---|---|---|" + "---|" * len(_COLUMNS) + "---|"]
    for name, res in record["results"].items():
        for level, v in res["levels"].items():
            f = v["fastest"]
            ratio = v["default_over_anchor"]
            rows.append(f"| {name} | {float(level):.0e} | {_cell(f, 'default')} | {_best_splitting(f)} | "
                        + " | ".join(_cell(f, m) for m, _ in _COLUMNS)
                        + f" | {'—' if ratio is None else f'{ratio:.2f}'} |")
    return "\n".join(rows) + (
        "\n\nEach cell: the fastest run whose max error over 200 output times, relative to the state's range, "
        "is within the level (best of 3 after a first call; the whole call with the values at the 200 times). "
        "`solve` (default): no solver given, swept over rtol 1e-4 … 1e-13 (the Gauss solver below "
        "64 components and on Kepler's problem, a splitting method on the chains); best fixed scheme: "
        "`SplittingComposition(scheme=…)` over the same sweep, the fastest scheme; Diffrax rtol 1e-5 … 1e-14; "
        "\"never\": none of its runs got there; —: not separable.")


def splitting_nls(record: dict) -> str:
    rows = ["| rtol | `SplittingComposition()`: time, error at T, mass drift | Gauss (the default) | "
            "split-step Yoshida-4 | ETDRK4 |",
            "|---|---|---|---|---|"]
    for r in record["default"]:
        cells = []
        for rival in ("gauss", "yoshida4", "etdrk4"):
            best = r["against"][rival]
            cells.append("never" if best is None else f"{_ms(best['seconds'])} (×{best['ratio']:.2g})")
        rows.append(f"| {r['rtol']:.0e} | {_ms(r['seconds'])}, {r['error']:.1e}, {r['mass_drift']:.0e} "
                    f"({r['scheme']}, {r['steps']} steps) | " + " | ".join(cells) + " |")
    return "\n".join(rows) + (
        f"\n\nThe soliton on M = {record['points']} points over [0, {record['T']:g}], against its exact solution. "
        "Each rival cell: its fastest run at most twice as far from the exact solution as the splitting's, and "
        "the splitting's time over it (×: below 1, the splitting is faster).")


def splitting_long(record: dict) -> str:
    rows = ["| system | scheme | steps | h (the [0, 100] step; blew up at) | time | max \\|H/H0 − 1\\| | by tenth of the "
            "interval |", "|---|---|---|---|---|---|---|"]
    for r in record["rows"]:
        tenths = " ".join(f"{x:.0e}" for x in r["energy_rel_by_tenth"])
        blew = ", ".join(f"{h:.3g}" for h in r["blew_up_at_h"]) or "—"
        rows.append(f"| {r['system']} | {r['scheme']} | {r['steps']:,} | {r['h']:.3g} ({r['probe_h']:.3g}; {blew}) | "
                    f"{r['seconds']:.3g} s | {r['energy_rel_max']:.1e} | {tenths} |")
    return "\n".join(rows)




def splitting_solar(record: dict) -> str:
    rows = ["| method | setting | time | position error at T (AU) | max \\|H/H0 − 1\\| |", "|---|---|---|---|---|"]
    named = {"atlasnn": "GaussCollocation (rebound_anchor.json)", "ias15": "REBOUND IAS15 (rebound_anchor.json)",
             "whfast": "REBOUND WHFast (rebound_anchor.json)"}
    for r in record["rows"] + record["from_rebound_anchor"]:
        rows.append(f"| {named.get(r['method'], r['method'])} | {r['setting']:g} | {_ms(r['seconds'])} | "
                    f"{r['position_error_au']:.1e} | {r['energy_error']:.1e} |")
    return "\n".join(rows)


def splitting_breakdown(record: dict) -> str:
    rows = ["| FPUT-β N | scheme, steps (tries) | whole call | pilots | march | checks and retries | dense output "
            "(200 times) |", "|---|---|---|---|---|---|---|"]
    for r in record["rows"]:
        rows.append(f"| {r['particles']} | {r['scheme']}, {r['steps']} ({r['tries']}) | {_ms(r['whole_s'])} | "
                    f"{_ms(r['pilot_s'])} | {_ms(r['march_s'])} | {_ms(r['checks_and_retries_s'])} | "
                    f"{_ms(r['dense_s'])} |")
    need = record["steps_needed"]
    counts = ", ".join(f"{x['steps']}: {x['error_over_tolerance']:.2g}" for x in need["rows"])
    return "\n".join(rows) + (
        f"\n\n`solve` with no solver given at rtol {record['rows'][0]['rtol']:g} over [0, {record['T']:g}]; each "
        f"part the best of {record['repeats']} after a first call; march: the chosen scheme and step count given, with no pilot "
        "and no check; checks and retries: the rest of the solve. On the chain of "
        f"{need['particles']}, the error of {need['scheme']} over the tolerance by step count (against "
        f"Sofroniou–Spaletta 10 with 4 000 steps): {counts}; the default took {need['default_steps']}.")


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.2g} µs"


def _counted(run: dict | None, what: str) -> str:
    if run is None:
        return "never"
    return f"{what}{_ms(run['seconds'])}, {run['evaluations']:,} evaluations ({_us(run['seconds_per_evaluation'])} each)"


def rival_costs(record: dict) -> str:
    nls = record["nls"]
    rows = ["| NLS, error at T ≤ | `solve` (default) | ETDRK4 | default / ETDRK4 |", "|---|---|---|---|"]
    for level in nls["levels"]:
        mine, rival, ratio = level["default"], level["etdrk4"], level["ratio"]
        rows.append(f"| {level['level']:.0e} | "
                    + _counted(mine, "" if mine is None else f"rtol {mine['rtol']:.0e}, s = {mine['stages']}: ")
                    + " | " + _counted(rival, "" if rival is None else f"{rival['steps']} steps: ")
                    + f" | {'—' if ratio is None else f'{ratio:.2f}'} |")
    rows += ["", "| `SplittingComposition()`, rtol | time, error at T | pilot | march | check | scheme, steps | a flow of "
             "the march |", "|---|---|---|---|---|---|---|"]
    for r in nls["splitting"]:
        march = f"({_ms(r['march_s'])} alone) in the pilot" if r.get("march_from_pilot") else _ms(r["march_s"])
        rows.append(f"| {r['rtol']:.0e} | {_ms(r['seconds'])}, {r['error']:.1e} | {_ms(r['pilot_s'])} | {march} | "
                    f"{_ms(r['check_s'])} | {r['scheme']}, {r['steps']} | {_us(r['march_seconds_per_flow'])} |")
    solar = record["solar"]
    rows += ["", "| outer solar system | setting | time | position error (AU) | max \\|H/H0 − 1\\| | evaluations |",
             "|---|---|---|---|---|---|"]
    for r in solar["rows"]:
        label = "`solve` (default), rtol" if r["method"] == "atlasnn" else r["method"] + (", ε" if "IAS15" in r["method"]
                                                                                          else ", days")
        rows.append(f"| {label} | {r['setting']:.4g} | {_ms(r['seconds'])} | {r['position_error_au']:.1e} | "
                    f"{r['energy_error']:.1e} | {r['evaluations']:,} ({_us(r['seconds_per_evaluation'])} each) |")
    return "\n".join(rows) + (
        f"\n\nNLS: M = {nls['points']} points over [0, {nls['T']:g}], the end state against the exact soliton; each cell "
        "the fastest run within the error (the default swept over rtol 1e-4 … 1e-12, atol = rtol/100; ETDRK4 over "
        "100 … 12 800 steps); an evaluation: for the default one stage of one fixed-point iteration (the nonlinear "
        "field and the linear part's solve there), for ETDRK4 one of the four nonlinear fields of a step. The "
        "splitting's march: its scheme and step count given, no pilot and no check; a flow: one linear and one "
        f"nonlinear flow. Outer solar system: {solar['T_days']:g} days, {solar['times']} output times, errors "
        f"against {solar['reference']}; an evaluation: the field (forces) at one state, the default's its "
        "iterations × stages, REBOUND's counted by a callback in a run of their own; the Wisdom–Holman runs in "
        "Jacobi coordinates, WHFast with its 17th-order and second correctors and the lazy kernel.")


MAKERS = {"splitting": splitting, "splitting_nls": splitting_nls, "splitting_long": splitting_long,
          "splitting_solar": splitting_solar, "splitting_breakdown": splitting_breakdown, "rival_costs": rival_costs}
