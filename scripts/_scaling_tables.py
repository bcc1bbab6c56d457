"""The tables of docs/SOLVER_MEASURED.md's "At size" (made by ``scripts/solver_doc.py``, which owns the blocks,
the pages and the check), from docs/benchmarks/gauss_scaling.json (``python -m
benchmarks.gauss_scaling``): ``scaling`` (µs per window against d; FPUT chains against Diffrax) and
``orders_at_size`` (the stage count on large systems, with the field's evaluations)."""

from __future__ import annotations

from _doc_format import milliseconds as _ms

RECORDS = {"scaling": "docs/benchmarks/gauss_scaling.json", "orders_at_size": "docs/benchmarks/gauss_scaling.json"}


def scaling(record: dict) -> str:
    first = "first call (compiles)" if record.get("command", "").startswith("ATLASNN_CACHE_DIR=off") else "first call"
    rows = ["| system | d | s | windows | iterations / window | µs / window | of which the field's evaluations | "
            f"{first} |", "|---|---|---|---|---|---|---|---|"]
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


def _cell(seconds: float, error: float, evaluations: int) -> str:
    return f"{_ms(seconds)}, {error:.0e}, {evaluations / 1e3:.3g}k"


def orders_at_size(record: dict) -> str:
    rows = record.get("orders") or []
    orders = sorted({r["stages"] for r in rows})
    default = {r["rtol"]: r["stages"] for r in record.get("fput", [])}
    out = ["| system, d | rtol | " + " | ".join(f"s = {s}" for s in orders) + " | Diffrax Dopri8, fastest as accurate "
           "as the fastest s |", "|---|---|" + "---|" * len(orders) + "---|"]
    for key in dict.fromkeys((r["system"], r["d"], r["rtol"]) for r in rows):
        group = {r["stages"]: r for r in rows if (r["system"], r["d"], r["rtol"]) == key}
        cells = []
        for s in orders:
            r = group.get(s)
            text = "" if r is None else _cell(r["seconds"], r["error"], r["evaluations"])
            cells.append(f"**{text}**" if r is not None and default.get(key[2]) == s else text)
        best = min(group.values(), key=lambda r: r["seconds"])
        rival = best["dopri8"]
        cells.append("none within 2× of its error" if rival is None else
                     f"{_cell(rival['seconds'], rival['error'], rival['evaluations'])} (rtol {rival['rtol']:.0e}): "
                     f"s = {best['stages']} {best['seconds'] / rival['seconds']:.2g}×")
        out.append(f"| {key[0]}, {key[1]} | {key[2]:.0e} | " + " | ".join(cells) + " |")
    gaps = ", ".join(f"{name} {gap:.0e}" for name, gap in dict.fromkeys((r["system"], r["reference_gap"]) for r in rows))
    return "\n".join(out) + ("\n\nEach cell: the whole call's time with the values at 200 times, the largest error over "
                             "them relative to the state's range, and the evaluations of the field at one state (s × "
                             "the iterations; Dopri8: 13 a step). Bold: the stage count the default takes at that "
                             "rtol. Reference: the Gauss method at s = 16 and rtol 1e-14 (its gap to Dopri8 at rtol "
                             f"1e-14: {gaps}); a Dopri8 run (rtol 1e-6 … 1e-13) counts as accurate within 2× of the "
                             "error; \"s = k m×\": that stage count's time over Dopri8's.")


MAKERS = {"scaling": scaling, "orders_at_size": orders_at_size}
