"""The measured tables of docs/PDE_MEASURED.md (made by ``scripts/solver_doc.py``, which owns the
blocks, the pages and the check): ``pde``, ``pde_scaling`` and ``pde_long`` from
docs/benchmarks/nls_pde.json, nls_pde_scaling.json and nls_pde_long.json (``python -m
benchmarks.nls_pde``), ``sine_gordon`` from docs/benchmarks/sine_gordon_pde.json (``python -m benchmarks.sine_gordon_pde``),
``fput`` from docs/runs/fput/recurrence.json and long.json (``python
examples/fput_recurrence.py``)."""

from __future__ import annotations

import json
from pathlib import Path

from _doc_format import milliseconds as _ms

ROOT = Path(__file__).resolve().parents[1]

RECORDS = {"pde": "docs/benchmarks/nls_pde.json", "sine_gordon": "docs/benchmarks/sine_gordon_pde.json", "pde_scaling": "docs/benchmarks/nls_pde_scaling.json",
           "pde_long": "docs/benchmarks/nls_pde_long.json", "fput": "docs/runs/fput/recurrence.json"}


NAMES = {"strang": "Strang", "yoshida4": "Yoshida-4", "etdrk4": "ETDRK4", "tsit5": "Diffrax Tsit5",
         "kvaerno5": "Diffrax Kvaerno5", "verlet": "Störmer–Verlet"}


def _against(row: dict, rival: str) -> str:
    best = row["against"][rival]
    if best is None:
        return "never"
    what = f"{best['steps']} steps" if "steps" in best else f"rtol {best['rtol']:g}"
    return f"{_ms(best['seconds'])}, {best['error']:.1e} ({what}): ×{best['ratio']:.2g}"


def _runs(record: dict) -> str:
    """One table per grid: atlasnn's runs against the fastest rival run at least as accurate."""
    out = []
    for run in record["runs"]:
        rivals = run.get("rivals", ["strang", "yoshida4", "tsit5"])
        names = [NAMES.get(r, r) for r in rivals]
        rows = [f"**M = {run['points']}** (length {run['length']:g}, T = {run['T']:g})", "",
                "| rtol = atol | atlasnn: time, error (s, windows) | " + ("mass drift | " if "strang" in run else "")
                + " | ".join(names) + " |", "|---|---|" + ("---|" if "strang" in run else "") + "---|" * len(rivals)]
        for r in run["atlasnn"]:
            if r["stages_given"] is not None:
                continue
            tol = "defaults (1e-11, 1e-13)" if r["rtol"] is None else f"{r['rtol']:g}"
            rows.append(f"| {tol} | {_ms(r['seconds'])}, {r['error']:.1e} (s = {r['stages']}, {r['windows']}) "
                        + (f"| {r['mass_drift']:.0e} " if "strang" in run else "") + "| "
                        + " | ".join(_against(r, rival) for rival in rivals) + " |")
        sweep = [r for r in run["atlasnn"] if r["stages_given"] is not None]
        if sweep:
            rows += ["", "Other stage counts: " + "; ".join(
                f"rtol {'default' if r['rtol'] is None else format(r['rtol'], 'g')}, s = {r['stages']}: "
                f"{_ms(r['seconds'])}, {r['error']:.1e}" for r in sweep) + "."]
        plain = run.get("atlasnn_without_linear_part") or []
        for r in plain:
            rows += ["", f"Without the linear part (the fixed-point iteration), rtol {r['rtol']:g}: "
                         f"{_ms(r['seconds'])}, {r['error']:.1e}, {r['windows']} windows."]
        first = run["atlasnn"][0]
        rows += ["", f"The first call at the defaults (compiling): {first['first_call_seconds']:.1f} s."]
        if "strang" in run:
            split_mass = max(p["mass_drift"] for p in run["strang"] + run["yoshida4"])
            if "etdrk4" in run:
                rows += ["", f"ETDRK4's mass drifts reach {max(p['mass_drift'] for p in run['etdrk4']):.0e} (it keeps "
                             "no invariant)."]
            rows += ["", f"The split-step runs' mass drifts reach {split_mass:.0e} (FFT round-off, accumulated over "
                         "their steps)."]
        out.append("\n".join(rows))
    return "\n\n".join(out)


def pde(record: dict) -> str:
    return _runs(record) + (
        "\n\nErrors: max over the grid of |z(T) − the exact soliton|, relative to its amplitude 1 (the grid's own error "
        "is the floor). \"×k\": atlasnn's time over the fastest run of that method at least as accurate, within 2× of its error (Strang, "
        "Yoshida-4 and ETDRK4 100 … 12 800 steps, Tsit5 rtol 1e-6 … 1e-12 and Kvaerno5 from 1e-6 until a call took over a minute, atol = rtol/100); "
        "\"never\": none of its runs was. One core, compiled, the whole call, best of 3 (of 1 for a call of over 20 s).")


def sine_gordon(record: dict) -> str:
    return _runs(record) + (
        "\n\nErrors: max over the grid of |z(T) − the exact breather| (u and u_t). \"×k\": atlasnn's time over the "
        "fastest run of that method at least as accurate, within 2× of its error (Störmer–Verlet and Yoshida-4 with the spectral Laplacian, "
        "100 … 12 800 steps, Tsit5 rtol 1e-6 … 1e-12 and Kvaerno5 from 1e-6 until a call took over a minute, atol = rtol/100); "
        "\"never\": none of its runs was. One core, compiled, the whole call, best of 3 (of 1 for a call of over 20 s).")


def pde_scaling(record: dict) -> str:
    rows = ["| M | windows (s) | iterations / window | µs / iteration | µs / window | first call |", "|---|---|---|---|---|---|"]
    for r in record["rows"]:
        rows.append(f"| {r['points']} | {r['windows']} ({r['stages']}) | {r['iterations_per_window']:.1f} | "
                    f"{r['us_per_iteration']:.3g} | {r['us_per_window']:.3g} | {r['first_call_seconds']:.1f} s |")
    return "\n".join(rows) + ("\n\nThe NLS soliton over t ∈ [0, 2] in windows of 0.05 (`GaussCollocation(h=0.05, stages=16)`: "
                              "the same windows at every size; the coarse grids under-resolve the soliton).\n\n"
                              "![Time per iteration against M](benchmarks/nls_pde_scaling.png)")


def _fput_line(record: dict) -> str:
    rec = record["recurrence"]
    back = "no return found" if rec is None else \
        f"{100 * rec['mode1_fraction']:.1f} % of the energy back in mode 1 at t = {rec['t']:.0f}"
    return (f"over [0, {record['T']:g}]: {back}; {record['windows']} windows (s = {record['stages']}, h = "
            f"{record['h']:.3g}) in {record['seconds']:.1f} s with the first call; the largest |H(t)/H(0) − 1| "
            f"along the output ({len(record['times'])} times) {record['energy_error_max']:.1e}")


def pde_long(record: dict) -> str:
    rows = ["| method | time | error at T | largest mass drift | largest energy drift |", "|---|---|---|---|---|"]
    for name, label in (("atlasnn", "atlasnn, defaults"), ("yoshida4", "Yoshida-4 split-step")):
        r = record[name]
        what = f"{r['windows']} windows, s = {r['stages']}" if name == "atlasnn" else f"{r['steps']} steps"
        rows.append(f"| {label} ({what}) | {_ms(r['seconds'])} | {r['error_at_T']:.1e} | {r['mass_drift_max']:.0e} | "
                    f"{r['energy_drift_max']:.0e} |")
    return (f"The soliton over t ∈ [0, {record['T']:g}] (M = {record['points']}: it travels {record['travel']:.0f} "
            f"widths), mass and energy at {len(record['times'])} times:\n\n" + "\n".join(rows)
            + "\n\n![Mass and energy over the long run](benchmarks/nls_pde_long.png)")


def fput(record: dict) -> str:
    text = ("FPUT-α, N = 32, α = 0.25, Fermi's start, " + _fput_line(record) + ".\n\n"
            "![The energies of modes 1–5 over the recurrence](runs/fput/recurrence.png)")
    long = ROOT / "docs" / "runs" / "fput" / "long.json"
    if long.is_file():
        record = json.loads(long.read_text(encoding="utf-8"))
        text += ("\n\nThe same chain " + _fput_line(record) + " — the returns of mode 1 themselves come and go: the "
                 "super-recurrence (`" + record["command"] + "`).\n\n"
                 "![Mode energies over 10⁶ time units](runs/fput/long.png)")
    return text


MAKERS = {"pde": pde, "sine_gordon": sine_gordon, "pde_scaling": pde_scaling, "pde_long": pde_long, "fput": fput}
