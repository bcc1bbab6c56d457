"""The measured tables of docs/LEARNED_H_MEASURED.md (made by ``scripts/solver_doc.py``, which owns the
blocks, the pages and the check): ``learned`` from docs/benchmarks/learned_h.json (``python -m
benchmarks.learned_h``), ``learned_regimes`` from docs/benchmarks/learned_h_regimes.json (``python -m
benchmarks.learned_h_regimes``), ``learned_more_data`` from the same benchmark run with ``--trajectories``
(docs/benchmarks/learned_h_more_data.json)."""

from __future__ import annotations

import math
import statistics

RECORDS = {"learned": "docs/benchmarks/learned_h.json",
           "learned_regimes": "docs/benchmarks/learned_h_regimes.json",
           "learned_more_data": "docs/benchmarks/learned_h_more_data.json"}


def learned(record: dict) -> str:
    methods = list(dict.fromkeys(r["method"] for r in record["rows"]))
    cell = lambda r: ("failed" if not math.isfinite(r["state_error"])  # noqa: E731
                      else f"{r['state_error']:.1e} / {r['energy_error']:.1e}")
    rows = ["| system | σ | " + " | ".join(f"{m}: state / energy error" for m in methods) + " |",
            "|---|---|" + "---|" * len(methods)]
    for key in dict.fromkeys((r["system"], r["sigma"]) for r in record["rows"]):
        hit = {r["method"]: r for r in record["rows"] if (r["system"], r["sigma"]) == key}
        best = min(hit.values(), key=lambda r: r["state_error"])["method"]
        rows.append(f"| {key[0]} | {key[1]:g} | " + " | ".join(
            (f"**{cell(hit[m])}**" if m == best else cell(hit[m])) if m in hit else "—" for m in methods) + " |")
    seconds = {m: statistics.median(r["train_seconds"] for r in record["rows"] if r["method"] == m) for m in methods}
    two_body = {r["method"]: r["energy_mse"] for r in record["rows"] if r["system"] == "two-body" and r["sigma"] == 0}
    ahead = [r for r in record["rows"] if r["method"] == methods[0]]
    wins = sum(1 for r in ahead for h in record["rows"] if h["method"] == "HNN" and (h["system"], h["sigma"]) ==
               (r["system"], r["sigma"]) and r["state_error"] * 10 <= h["state_error"]
               and r["energy_error"] * 10 <= h["energy_error"])
    text = "\n".join(rows) + (
        f"\n\nEach cell: the held-out state error (the largest over [0, {record['horizon']:g}]) / the true energy's "
        f"median relative error along the prediction, each the median over three held-out states; bold: the smallest "
        f"state error of the row. {record['steps']} Adam steps each (rate {record['rate']:g}), one core; median "
        "training time " + ", ".join(f"{m} {seconds[m]:.0f} s" for m in methods) + ". "
        f"{methods[0].capitalize()} is 10× below the HNN on both errors in {wins} of {len(ahead)} cases. "
        "Figure: [learned_h.png](benchmarks/learned_h.png).")
    if two_body:
        text += ("\n\nGreydanus et al. (2019, Table 1) report, for their two-body task, an energy MSE along rollouts of "
                 "6.3e-2 for their baseline network and 3.9e-5 for the HNN. The same quantity here (the true energy's "
                 "mean squared error along the held-out predictions, σ = 0): " + ", ".join(
                     f"{m} {v:.1e}" for m, v in two_body.items()) +
                 "; their data, network and horizon differ from these, so the numbers are beside each other, not "
                 "a like-for-like comparison.")
    return text


def _state(row: dict | None) -> str:
    if row is None:
        return "—"
    if not math.isfinite(row["state_error"]):
        return "failed"
    return (f"{row['state_error']:.1e}" + ("" if row["trusted"] else " (u)")
            + (" (stopped)" if row.get("stopped") else ""))


#: the table's columns: (observed, the method's role) and their heads; a method's role is its label
#: with the solver trained through left out (leapfrog for separable systems, Gauss for the others)
_COLUMNS = [(("all", "HNN"), "HNN"), (("all", "HNN, smoothed"), "HNN, smoothed differences"),
            (("all", "through"), "through the solver"),
            (("all", "through, end to end"), "through the solver, end to end, starts fitted"),
            (("positions", "through"), "known form through the solver, positions only")]


def _role(row: dict) -> tuple[str, str]:
    method = row["method"].replace("through leapfrog", "through").replace("through Gauss", "through")
    return row["observed"], method


def learned_regimes(record: dict, more_data: bool = False) -> str:
    """The regimes' table; ``more_data``: a run with ``--trajectories`` (its count and every result's
    training loss over the noise's own in the note)."""
    rows = record["rows"]
    columns = [c for c, _ in _COLUMNS]
    head = [h for _, h in _COLUMNS]
    present = [k for k, c in enumerate(columns) if any(_role(r) == c for r in rows)]
    throughs = [k for k in (2, 3) if k in present]
    ratios = ["HNN / " + ("through the solver" if k == 2 else "end to end") for k in throughs]
    out = ["| system | Δt·ω_max | σ | " + " | ".join([head[k] for k in present] + ratios) + " |",
           "|---|---|---|" + "---|" * (len(present) + len(ratios))]
    for key in dict.fromkeys((r["system"], r["spacing"], r["sigma"]) for r in rows):
        hit = {_role(r): r for r in rows if (r["system"], r["spacing"], r["sigma"]) == key}
        cells = [_state(hit.get(columns[k])) if k < 4 else _known(hit.get(columns[k])) for k in present]
        cells += [_ratio(hit.get(columns[0]), hit.get(columns[k])) for k in throughs]
        out.append(f"| {key[0]} | {key[1]:g} | {key[2]:g} | " + " | ".join(cells) + " |")
    systems = list(dict.fromkeys(r["system"] for r in rows))
    per_step = {label: " / ".join(_median_step(rows, column, name) for name in systems)
                for column, label in zip(columns, head) if any(_role(r) == column for r in rows)}
    solvers = sorted({r["system"] for r in rows if "through Gauss" in r["method"]})
    return "\n".join(out) + (
        f"\n\nEach cell: the held-out state error, the largest over {record['horizon_factor']}× the training span "
        "relative to the state's range, the median over three held-out initial states; (u): the result was marked "
        "untrusted; (stopped): the training stopped early, its reason in the record's `stopped`. "
        f"{record['observations']} observations a trajectory{_trajectories(rows) if more_data else ''}; noise σ "
        "relative to each component's rms; "
        f"{record['steps']} Adam steps (rate {record['rate']:g}) for every method, the network "
        f"{record['network']}; the solver: leapfrog, {record['leapfrog_per_interval']} steps per observation "
        "interval" + (f" (for {', '.join(solvers)}, not separable: the Gauss solver, {_gauss(record['gauss'])})"
                      if solvers else "")
        + f"; segments of {record['ahead']} observations" + (
            f" ({record['position_ahead']} end to end from positions only, a known form: {_known_forms(systems)}, "
            f"with the masses given, at rate {record['known_rate']:g}; the largest relative error of its parameters)"
            if 4 in present else "")
        + ". The last observed trajectory held out whole where every component is observed. Median time per Adam "
        "step after the first (which compiles): "
        + ", ".join(f"{label} {ms} ms" for label, ms in per_step.items()) + f" ({' / '.join(systems)})."
        + (_noise_ratios(rows) if more_data else "") + _guide(rows, record["horizon_factor"]))


def learned_more_data(record: dict) -> str:
    return learned_regimes(record, more_data=True)


def _trajectories(rows: list) -> str:
    """The observed trajectories a system (a run with ``--trajectories``: one count for every system)."""
    return f", {rows[0]['trajectories']} trajectories a system"


def _noise_ratios(rows: list) -> str:
    """Each result's training loss over the noise's own (the trust rule's line is 3), where recorded."""
    ratios = [(r, r["loss"] / r["noise_loss"]) for r in rows if r.get("noise_loss")]
    if not ratios:
        return ""
    return (" Training loss over the noise's own (above 3: far above the noise): " + "; ".join(
        f"{r['system']} {r['method']} {q:.2g}" for r, q in ratios) + ".")


def _gauss(settings: dict) -> str:
    """The Gauss solver's settings in the benchmark, in words."""
    rtol = f"{settings['rtol']:g}".replace("e-0", "e-")  # 1e-7, as the pages write it
    return (f"{settings['stages']} stages at rtol {rtol}, up to {settings['max_windows']} windows a "
            f"segment, {settings['positions_max_windows']} for the known form from positions")


#: each system's known form's parameters, as the table's note names them
_PARAMETERS = {"pendulum": "the pendulum's g", "spring-chain": "the chain's k and β", "two-body": "the two bodies' μ",
               "three-body": "the three bodies' G", "double-pendulum": "the double pendulum's g"}


def _known_forms(systems: list) -> str:
    return ", ".join(_PARAMETERS.get(name, name) for name in systems)


def _median_step(rows: list, column: tuple, system: str) -> str:
    """The median time per Adam step, in ms, of a method's rows on one system (—: none timed)."""
    times = [1e3 * r["seconds_per_step"] for r in rows
             if _role(r) == column and r["system"] == system and r["seconds_per_step"] is not None]
    return f"{statistics.median(times):.2f}" if times else "—"


def _guide(rows: list, horizon_factor: float) -> str:
    """How the results' own guide to extrapolation (``expected_error`` over the same horizon, on the
    state error's scale) compares with the held-out error the table shows; a guide at its ceiling
    (2√2 of the data's size: no skill expected) is counted apart."""
    pairs = [(r["expected_state_error"], r["state_error"], _ceiling(r, horizon_factor)) for r in rows
             if r.get("expected_state_error") is not None and math.isfinite(r["state_error"]) and r["state_error"] > 0]
    if not pairs:
        return ""
    capped = [m for _, m, top in pairs if top]
    ratios = [e / m for e, m, top in pairs if not top]
    within = sum(0.5 <= q <= 2.0 for q in ratios)
    below = [q for q in ratios if q < 1.0]
    text = (f"\n\nEach result's own guide to the same horizon (`expected_error`, from its drift over the data's "
            f"span, no reference used) against the held-out error measured: on {len(capped)} of {len(pairs)} "
            "results the guide is at its ceiling (no skill expected)"
            + (f", where the measured error is {min(capped):.2g}–{max(capped):.2g} of the range" if capped else ""))
    if ratios:
        text += (f"; on the other {len(ratios)} it is within 2× of the measured error on {within}, above it on "
                 f"{len(ratios) - len(below)}, below it on {len(below)}"
                 + (f" (by up to {1 / min(below):.1f}×)" if below else "")
                 + f"; median guide / measured {statistics.median(ratios):.2g}")
    return text + "."


def _ceiling(row: dict, horizon_factor: float) -> bool:
    """Whether a row's guide is at its ceiling, 2√2 of the data's size, at ``horizon_factor`` times
    the data's span."""
    drift = row.get("drift")
    if not isinstance(drift, dict):
        return False
    grown = 2 * math.sqrt(3) * max(drift["drift"], drift["floor"]) * horizon_factor
    return grown >= 2 * math.sqrt(2) * (1 - 1e-9)


def _known(row: dict | None) -> str:
    return "—" if row is None else f"{_state(row)}; parameters {row['parameter_error']:.1%} off"


def _ratio(hnn: dict | None, through: dict | None) -> str:
    if not (hnn and through and math.isfinite(hnn["state_error"]) and math.isfinite(through["state_error"])):
        return "—"
    return f"{hnn['state_error'] / through['state_error']:.2g}"


MAKERS = {"learned": learned, "learned_regimes": learned_regimes, "learned_more_data": learned_more_data}
