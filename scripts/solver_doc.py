"""The measured tables of the Benchmarks pages (docs/SOLVER_MEASURED.md, docs/BENCHMARKS.md, …), made from the committed records.

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
* ``everyday``: docs/benchmarks/everyday.json (``python -m benchmarks.everyday``);
* ``scaling`` and ``orders_at_size``: docs/benchmarks/gauss_scaling.json (``python -m benchmarks.gauss_scaling``,
  ``scripts/_scaling_tables.py``);
* ``time_transform``: docs/benchmarks/time_transform.json (``python -m benchmarks.time_transform``);
* ``rebound``: docs/benchmarks/rebound_anchor.json (``python -m benchmarks.rebound_anchor``);
* ``gradients``: docs/benchmarks/gauss_gradients.json (``python -m benchmarks.gauss_gradients``, docs/JAX.md);
* ``learned`` and ``learned_regimes``: docs/LEARNED_H_MEASURED.md (``scripts/_learned_tables.py``);
* ``pde`` and ``fput``: docs/PDE_MEASURED.md (``scripts/_pde_tables.py``).
* ``splitting``, ``splitting_nls``, ``splitting_long``, ``splitting_solar``, ``splitting_breakdown``, ``rival_costs``: docs/SPLITTING_MEASURED.md (``scripts/_splitting_tables.py``).

The prose around the tables is written by hand; a few of its key numbers (and the machines
PERFORMANCE.md names) are checked against their records all the same (``PROSE`` below): each check
makes, from its record, the words a page must hold, and a page without them fails, in either mode,
with the words to write.

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
sys.path.insert(0, str(Path(__file__).resolve().parent))
import _pde_tables as pde_tables  # noqa: E402  (the PDE page's tables, beside this script)
import _scaling_tables as scaling_tables  # noqa: E402  (the tables of SOLVER_MEASURED.md's "At size")
import _learned_tables as learned_tables  # noqa: E402  (the tables of LEARNED_H_MEASURED.md)
import _splitting_tables as splitting_tables  # noqa: E402  (the tables of SPLITTING_MEASURED.md)
from _doc_format import milliseconds as _ms  # noqa: E402

PAGES = [ROOT / "docs" / "SOLVER_MEASURED.md", ROOT / "docs" / "BENCHMARKS.md", ROOT / "docs" / "JAX.md",
         ROOT / "docs" / "LEARNED_H_MEASURED.md", ROOT / "docs" / "PDE_MEASURED.md", ROOT / "docs" / "SPLITTING_MEASURED.md"]
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
    "everyday": "docs/benchmarks/everyday.json",
    "time_transform": "docs/benchmarks/time_transform.json",
    "rebound": "docs/benchmarks/rebound_anchor.json",
    "gradients": "docs/benchmarks/gauss_gradients.json",
    **pde_tables.RECORDS,
    **scaling_tables.RECORDS,
    **splitting_tables.RECORDS,
    **learned_tables.RECORDS,
}
METHODS = [("gauss-adaptive", "Gauss, adaptive"), ("diffrax-dopri8", "Diffrax Dopri8"),
           ("diffrax-tsit5", "Diffrax Tsit5"), ("dop853", "SciPy DOP853"), ("yoshida4", "Yoshida-4"),
           ("collocation", "Collocation (random features)")]
_BLOCK = re.compile(r"(<!-- solver-doc: (\w+) -->\n)(.*?)(<!-- /solver-doc -->)", re.S)


def _load(name: str) -> dict | None:
    path = ROOT / RECORDS[name]
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


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
    return "\n".join(rows) + "\n\n" + _sweep(record)


def _sweep(record: dict) -> str:
    """The settings each method was run at, over every problem: what "never" was tried with."""
    settings: dict[str, set] = {}
    for prob in record["problems"].values():
        for r in prob["rows"]:
            settings.setdefault(r["method"], set()).add(r["setting"])
    parts = []
    for method, label in METHODS:
        got = sorted(settings.get(method, ()))
        if not got:
            continue
        if method == "yoshida4":
            parts.append(f"{label} {got[0]:,} … {got[-1]:,} steps over the interval".replace(",", " "))
        else:
            parts.append(f"{label} rtol {_g(got[-1])} … {_g(got[0])}")
    return ("Each method's sweep, over which \"never\" holds (atol = rtol/100; \"best\": its most accurate run): "
            + "; ".join(parts) + ".")


def _unpad(text: str) -> str:
    """1e-06 → 1e-6: exponents without their padding zero, as the prose writes them."""
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + ("-" if m.group(1) == "-" else "") + m.group(2), text)


def _e(x: float, digits: int = 0) -> str:
    """x with ``digits`` decimals in scientific notation: 1e-10, 2.4e-11."""
    return _unpad(f"{x:.{digits}e}")


def _g(x: float) -> str:
    """x as Python's g format writes it, unpadded: 1e-6, 2.3e-14."""
    return _unpad(f"{x:g}")


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
    anchors = []
    for kind, runs in record["runs"].items():
        med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        if "first_call" in med:  # Diffrax's Dopri8 on the same field: its first, compiling call
            anchors.append(f"{kind.split(', ')[-1]} {med['first_call']:.2f} s (then {med['second_call'] * 1e3:.0f} ms)")
            continue
        rows.append(f"| {kind} | {med['import']:.2f} s | {med['first_solve']:.2f} s | {med['first_program_call']:.2f} s "
                    f"| {med['second_solve_and_evaluation'] * 1e3:.1f} ms |")
    counts = sorted({len(runs) for runs in record["runs"].values()})
    many = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
    text = "\n".join(rows) + f"\n\nEach row: the median of {many} fresh processes; Hénon–Heiles unless the row names a problem."
    if anchors:
        text += (" Diffrax's Dopri8 on the same field (rtol 1e-10, 2 000 saved times, jitted), its first call in a "
                 "fresh process, compiling and solving: " + "; ".join(anchors) + ".")
    return text


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


_ANCHORS = (("diffrax-tsit5", "Diffrax Tsit5"), ("diffrax-dopri8", "Diffrax Dopri8"), ("yoshida4", "Yoshida-4"))


def everyday(record: dict) -> str:
    rows = ["| problem | max error / range ≤ | atlasnn.solve (rtol, s) | " + " | ".join(label for _, label in _ANCHORS)
            + " | atlasnn / the fastest |", "|---|---|---|" + "---|" * len(_ANCHORS) + "---|"]
    for name, res in record["results"].items():
        for level, v in res["levels"].items():
            g = v["gauss"]
            gauss = "never" if g is None else f"{_ms(g['seconds'])} ({g['setting']:.0e}, {g['stages']})"
            ran = {r["method"] for r in res["rows"]}
            cells = ["—" if m not in ran else "never" if v[m] is None else _ms(v[m]["seconds"]) for m, _ in _ANCHORS]
            ratio = "—" if v["ratio"] is None else f"{v['ratio']:.2f}"
            rows.append(f"| {name} | {float(level):.0e} | {gauss} | " + " | ".join(cells) + f" | {ratio} |")
    return "\n".join(rows) + ("\n\nEach cell: the fastest run whose max error over 200 times, relative to the state's range, is "
                              "within the level (best of 3 after a first call, the whole call with the values at the 200 "
                              "times); atlasnn.solve swept over rtol 1e-3 … 1e-12 with the stage count it picks; Diffrax "
                              "rtol 1e-3 … 1e-14; Yoshida-4 199 … 51 200 steps (separable problems only: — "
                              "elsewhere); \"never\": none of its runs got there.")


def time_transform(record: dict) -> str:
    rows = ["| problem | method | windows | call (solve) | max error | max \\|H/H0 − 1\\| (at T) |",
            "|---|---|---|---|---|---|"]
    for r in record["rows"]:
        if not r["finished"]:
            why = r["stopped"].removeprefix("the Gauss march ").split(" (rtol")[0]
            rows.append(f"| {r['problem']} | {r['method']} | {why} (after {r['first_call_seconds']:.0f} s) | | | |")
            continue
        error = f"{r['max_error']:.1e}"
        if r["trusted_until"] < r["T"]:
            error += f" (t ≤ {r['trusted_until']:.3g})"
        times = _ms(r["seconds"]) + (f" ({_ms(r['solve_seconds'])})" if r.get("solve_seconds") else "")
        method = r["method"] + (" → in τ" if "auto" in r["method"] and r.get("marched_in") == "tau" else "")
        rows.append(f"| {r['problem']} | {method} | {r['windows'] or '—'} | {times} | {error} "
                    f"| {r['energy_max_rel']:.1e} ({r['energy_end_rel']:.0e}) |")
    return "\n".join(rows) + (f"\n\nThe call: the solve and its values at {record['output_times']} times, best of "
                              f"{record.get('repeats', 3)} (in turns across the methods) "
                              f"after a first call; errors and energies at {record['measured_times']} times.")


def rebound(record: dict) -> str:
    names = {"atlasnn": "atlasnn.solve, rtol", "atlasnn, H with arrays": "atlasnn.solve, H with arrays, rtol",
             "ias15": "REBOUND IAS15, ε", "whfast": "REBOUND WHFast, dt (days)"}
    rows = ["| method | setting | time | largest position error (AU) | largest \\|H/H0 − 1\\| along the output |",
            "|---|---|---|---|---|"]
    for r in record["rows"]:
        extra = f" (s = {r['stages']}, {r['windows']} windows)" if r["method"].startswith("atlasnn") else ""
        rows.append(f"| {names[r['method']]} | {r['setting']:g}{extra} | {_ms(r['seconds'])} | "
                    f"{r['position_error_au']:.1e} | {r['energy_error']:.1e} |")
    gap = record.get("reference_gap_to_ias15_au")
    note = f" (IAS15 at ε = 1e-11 within {gap:.1e} AU of it: errors below that are at the reference's resolution)" \
        if gap is not None else ""
    return "\n".join(rows) + (f"\n\n{record['T_days']:.0e} days, 200 output times, one core. Reference: "
                              f"{record['reference']}{note}.")


def gradients(record: dict) -> str:
    k = record["kepler"]
    rows = ["| call | time | error at T |", "|---|---|---|"]
    for name, r in k["rows"].items():
        error = f"{r['error_at_T']:.1e}" if "error_at_T" in r else ""
        rows.append(f"| {name} | {_ms(r['time_ms'] / 1e3)} | {error} |")
    a = k["agreement"]
    text = "\n".join(rows) + (
        f"\n\n{k['windows']} windows (host). A gradient costs {k['grad_over_forward']:.1f}× the jitted forward solve "
        f"and {k['grad_over_diffrax_gauss_grad']:.2f}× Diffrax's gradient through `GaussLegendre`. On {a['windows']} "
        f"fixed windows (h = {a['h']:g}, T = {a['T']:g}) ∂z(T)/∂z0 agrees with Richardson-extrapolated central differences to "
        f"{a['vs_central_differences']:.0e} and with Diffrax's (RecursiveCheckpointAdjoint, the same steps) to "
        f"{a['vs_diffrax_gauss_legendre']:.0e}, relative to its largest entry.")
    over = "; ".join(f"{o['overhead_us']:.0f} µs with `max_windows={o['max_windows']}`" for o in record["call_overhead"])
    o = record["call_overhead"][0]
    text += (f"\n\nA jitted one-window call (Hénon–Heiles, t ∈ [0, 0.1]) costs beyond its window ({o['per_window_us']:.0f} µs "
             f"in a long run): {over}; the host `solve` of the same window {o['host_one_window_call_us']:.0f} µs.")
    rows = ["| states | `jax.vmap` | `jax.lax.map` | `solve_batch` |", "|---|---|---|---|"]
    for v in record["vmap"]:
        rows.append(f"| {v['states']} | {v['vmap_s']:.2f} s | {v['lax_map_s']:.2f} s | {v['solve_batch_s']:.2f} s |")
    return text + ("\n\nHénon–Heiles over [0, 10] from perturbed states, `max_windows="
                   f"{record['vmap'][0]['max_windows']}`:\n\n" + "\n".join(rows))


MAKERS = {"gradients": gradients, "suite": suite, "workprecision": workprecision, "energy": energy, "step_modes": step_modes, "batch": batch,
          "first_run": first_run, "stages": stages,
          "roundoff": roundoff, "orders": orders, "everyday": everyday,
          "rebound": rebound, "time_transform": time_transform, **pde_tables.MAKERS, **scaling_tables.MAKERS,
          **splitting_tables.MAKERS, **learned_tables.MAKERS}


# ------------------------------------------------------------------ key numbers of the prose
def _json(path: str) -> dict:
    return json.loads((ROOT / path).read_text(encoding="utf-8"))


def _builtin(problem: str) -> bool:
    return (ROOT / "src" / "atlasnn" / "experiments" / "configs" / f"{problem}.toml").is_file()


def _suite_range(rows: list[dict]) -> str:
    errors = [r["error_rel"] for r in rows]
    return f"{_e(min(errors))}–{_e(max(errors))}"


def _choosing_trajectory() -> list[str]:
    suite = [r for r in _json(RECORDS["suite"])["rows"] if r["status"] == "ok" and _builtin(r["problem"])]
    energy = _json(RECORDS["energy"])["methods"]
    wp = _json(RECORDS["workprecision"])["problems"]
    gauss, dopri8 = energy["gauss"], energy["diffrax-dopri8"]
    assert gauss["periods"] == 1e5, "energy_long.json: the prose says 10⁵ periods"
    adaptive = [1 / wp[name]["equal_accuracy"]["gauss-adaptive"]["ratio"] for name in ("kepler-e06-100", "kepler-e099-4")]
    best, ratios, equal = [], [], []
    for prob in wp.values():
        default = prob["equal_accuracy"]["gauss_default"]
        run = min((r for r in prob["rows"] if r["method"] == "collocation" and "error_rel" in r),
                  key=lambda r: r["error_rel"])
        best.append(run["error_rel"])
        equal.append(bool(prob["equal_accuracy"].get("collocation")))
        if default["error_rel"] <= 1e-11:
            ratios.append(run["seconds"] / default["seconds"])
    tta = next(s for s in _json("docs/benchmarks/time_to_accuracy.json")["summary"]
               if s["problem"] == "henon-heiles-long" and s["target"] == 1e-4)
    assert tta["reached"] == tta["seeds"], "time_to_accuracy.json: not every seed reached 1e-4 on Hénon–Heiles"
    return [f"{_suite_range(suite)} of the range at the defaults on every built-in problem",
            f"energy error at most {_e(gauss['energy_max_all'], 1)} over 10⁵ Kepler periods, Diffrax Dopri8's "
            f"{_e(dopri8['energy_max_all'], 1)}",
            f"{adaptive[0]:.2g}× faster on Kepler e = 0.6 over 100 periods, {adaptive[1]:.2g}× at e = 0.99",
            f"{_e(max(best))}–{_e(min(best))} at its tightest, on "
            + ("no problem" if not any(equal) else f"{sum(equal)} problems") + " as accurate as the default",
            f"at that tightest {min(ratios):.2g}–{max(ratios):.2g}× the default's time on the {len(ratios)} of "
            f"{len(wp)} problems where the default is within 1e-11",
            f"a max error of 1e-4 on Hénon–Heiles [0, 24π] | {tta['median_seconds']:.2g} s of training per seed there"]


def _diffrax_words() -> tuple[dict, dict, dict, dict]:
    record = _json("docs/benchmarks/diffrax_gauss.json")
    k, h = record["kepler"]["at_1e-10"], record["henon-heiles"]["at_1e-10"]
    return k["gauss-legendre"], k["dopri8"], h["gauss-legendre"], h["dopri8"]


def _choosing_diffrax() -> list[str]:
    g, d, _, _ = _diffrax_words()
    return [f"it reaches {_e(g['error_rel'], 1)} of the range in {g['seconds'] * 1e3:.1f} ms, where Dopri8 needs "
            f"{d['seconds'] * 1e3:.1f} ms for {_e(d['error_rel'], 1)}"]


def _from_diffrax() -> list[str]:
    g, d, hg, hd = _diffrax_words()
    return [f"`ConstantStepSize` at h = {g['h_label']} reaches {_e(g['error_rel'], 1)} in {g['seconds'] * 1e3:.0f} ms",
            f"Dopri8 needs rtol = atol = {_g(d['tol'])} to get there ({_e(d['error_rel'], 1)}, "
            f"{d['steps']:,} steps, {d['seconds'] * 1e3:.0f} ms: {d['seconds'] / g['seconds']:.1f}× the time)".replace(
                f"{d['steps']:,}", f"{d['steps']:,}".replace(",", " ")),
            f"{_e(hg['error_rel'], 1)} in {hg['seconds'] * 1e3:.1f} ms (h = {hg['h_label']}) against Dopri8's "
            f"{_e(hd['error_rel'], 1)} in {hd['seconds'] * 1e3:.1f} ms ({hd['seconds'] / hg['seconds']:.1f}×)"]


def _solver_suite() -> list[str]:
    rows = [r for r in _json(RECORDS["suite"])["rows"] if r["status"] == "ok"]
    e099 = next(r for r in rows if r["problem"] == "kepler-e099")
    rest = [r for r in rows if r is not e099]
    assert all(r["error_rel"] <= 1e-10 for r in rest), "suite.json: a problem above 1e-10 of the range"
    return [f"within 1e-10 of the range, all at {_suite_range(rest)}",
            f"Kepler e = 0.99 (not built in) is at {_e(e099['error_rel'])}, and the estimate, "
            + (f"{e099['effectivity']:.2g}× above it" if e099["effectivity"] >= 1
               else f"{e099['effectivity']:.2g} of it")]


def _machine(path: str) -> tuple[str, int]:
    m = _json(path)["machine"]
    return (m.get("lscpu") or {}).get("Model name", "?"), m["cpu_count"]


def _performance_machines() -> list[str]:
    cpus = {_machine(p) for p in ("docs/benchmarks/time_to_accuracy.json", "docs/benchmarks/device_accuracy_cpu.json")}
    host = _machine("docs/benchmarks/gpu/device_accuracy_gpu.json")
    gpu = _json("docs/benchmarks/gpu/device_accuracy_gpu.json")["result"]["device"]["kind"]
    most = _machine(RECORDS["workprecision"])
    words = lambda name: name.replace("(R)", "").replace(" Processor", "")  # noqa: E731
    assert len(cpus) == 1, f"time_to_accuracy.json and device_accuracy_cpu.json name two machines: {cpus}"
    (cpu, cores), = cpus
    return [f"a shared {most[1]}-core {words(most[0])} virtual machine (KVM)",
            f"a {cores}-core {words(cpu)} virtual machine for [time_to_accuracy.json]",
            f"a {host[1]}-core {words(host[0])} host with one lent {gpu} for the GPU records"]


def _choosing_limits() -> list[str]:
    runs = _json(RECORDS["first_run"])["runs"]
    cold = statistics.median(r["first_solve"] for r in runs["cold (cache off)"])
    warm = statistics.median(r["first_solve"] for r in runs["warm cache"])
    solar = statistics.median(r["first_solve"] for r in runs["cold (cache off), outer-solar"])
    size = _json("docs/benchmarks/outer_solar.json")["row"]["dimension"]
    return [f"{cold:.2f} s for a small system with the cache off, {warm:.2f} s when the program is on disk",
            f"{solar:.1f} s for the {size} components of the outer solar system"]


#: page → the words it must hold, each made from a record
PROSE = {
    "docs/BENCHMARKS.md": [_choosing_trajectory, _choosing_diffrax],
    "docs/LIMITATIONS.md": [_choosing_limits],
    "docs/DIFFRAX_MEASURED.md": [_from_diffrax],
    "docs/SOLVER_MEASURED.md": [_solver_suite],
    "docs/PERFORMANCE.md": [_performance_machines],
}


def prose_problems() -> list[str]:
    """Each key number of the prose that its page does not hold as its record makes it (whitespace
    and line breaks aside)."""
    out = []
    for page, makers in PROSE.items():
        text = " ".join((ROOT / page).read_text(encoding="utf-8").split())
        for make in makers:
            try:
                words = make()
            except (AssertionError, KeyError, StopIteration, FileNotFoundError) as exc:
                out.append(f"{page}: {make.__name__}: the record no longer says what the prose does ({exc!r})")
                continue
            out += [f"{page}: should say {w!r} (from its record)" for w in words if " ".join(w.split()) not in text]
    return out


def render(text: str) -> str:
    def one(match: re.Match) -> str:
        name = match.group(2)
        record = _load(name)
        if record is None:
            body = f"(no record yet: `{RECORDS[name]}`)\n"
        else:
            machine = record.get("machine") or {}
            load, model = machine.get("load_average"), (machine.get("lscpu") or {}).get("Model name")
            note = ""
            if model:  # each table names its machine: records of one page may come from different ones
                one = " (one core used)" if machine.get("cores_available") == 1 else ""
                note += f" On a {machine.get('cpu_count', '?')}-core {model}{one}."
            note += f" Load average {load[0]:.1f} while it ran." if load else ""
            updated = record.get("updated")
            if updated:  # a record whose named rows a later run replaced (``--update``)
                rerun = updated.get("problems") or updated.get("methods") or []
                note += f" The rows of {', '.join(rerun)} are from that run; "
                if "earlier_runs" in updated:  # several earlier runs, each with the rows it made
                    note += "; ".join(f"those of {', '.join(run['problems'])} from `{run['command'].strip()}`"
                                      for run in updated["earlier_runs"]) + "."
                else:
                    note += f"the others from an earlier one, `{updated['earlier'].strip()}`."
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
    prose = prose_problems()
    for line in prose:
        print(line)
    if args.check and stale:
        print("out of date: " + ", ".join(str(p.relative_to(ROOT)) for p in stale) + "; run python scripts/solver_doc.py")
        return 1
    return 1 if prose else 0


if __name__ == "__main__":
    sys.exit(main())
