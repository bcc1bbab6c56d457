"""The paper's claims, checked seed by seed: how often each holds in our runs, per profile.

Each results table of the paper makes, for every model, three claims about the release-form L2
error of the first state component (the headline row): that the model is better (or worse) than
the table's baseline, better than symplectic Euler (SE), and — implicitly — that its printed
value is what the method gives. For one experiment and one or more run directories (one per
profile), :func:`experiment_claims` counts the seeds in which each holds:

- *beats the baseline*: our L2 below the same seed's baseline L2 (the paper's sign of the
  improvement says whether it claims better or worse; we count the seeds that agree);
- *beats SE*: our L2 below SE's (deterministic, one value);
- *reaches the paper's value*: our L2 at or below the paper's printed value;
- for transfer experiments, *needs fewer target epochs than the baseline*, where the paper
  reports epochs.

Nothing here trains or reads figures: results.json files and ``atlasnn/data/paper_results.json``.
"""

from __future__ import annotations

from typing import Any, Mapping

from atlasnn.evaluation import TrainingRecord
from atlasnn.report._stats import load_paper, load_results


def _table_records(results: dict, column: str) -> list[TrainingRecord]:
    return [r for r in map(TrainingRecord.from_dict, results.get("runs") or []) if r.column == column and r.in_table]


def _by_seed(results: dict, column: str, state: str) -> dict[Any, float]:
    out = {}
    for r in _table_records(results, column):
        v = r.metric("l2_discrete", state)
        if v is not None:
            out[r.seed] = v
    return out


def _epochs_by_seed(results: dict, column: str) -> dict[Any, int]:
    return {r.seed: int(r.epochs) for r in _table_records(results, column) if r.epochs is not None}


def _se_value(results: dict, state: str) -> float | None:
    for row in results.get("integrators") or []:
        if row.get("column") == "se":
            return ((row.get("metrics") or {}).get("l2_discrete") or {}).get(state)
    return None


def _count(pairs: list[bool]) -> dict[str, int]:
    return {"k": sum(pairs), "n": len(pairs)}


def experiment_claims(runs: Mapping[str, Any]) -> dict:
    """The claims of one paper experiment, checked in each run: ``runs`` maps a profile name to
    a run directory or results dict (all of the same experiment).

    Returns ``{"experiment", "paper_experiment", "state", "baseline", "rows": [...]}``; each row has the model's
    ``column`` and ``label``, the ``claim`` in words, the paper's ``paper`` finding (True/False,
    or None when it makes none) with its numbers in ``paper_text``, and ``profiles``: per profile
    ``{"k": seeds where it holds, "n": seeds}``.
    """
    loaded = {name: load_results(r) for name, r in runs.items()}
    first = next(iter(loaded.values()))
    name = first.get("paper_experiment") or first["experiment"]
    paper = load_paper(name)
    state = first["state_names"][0]
    p_l2 = paper["rows"].get(f"l2_{state}", {})
    base = paper.get("baseline") or first["baseline"]
    labels = first.get("labels") or {}
    rows = []
    for column in first["columns"]:
        if column in ("se", base) or column not in p_l2:
            continue
        label = labels.get(column, column)
        p_val, p_base, p_se = p_l2.get(column), p_l2.get(base), p_l2.get("se")
        specs = [
            (f"{label} better than {labels.get(base, base)} (L2({state}))", p_val < p_base,
             f"{p_val:.3g} vs {p_base:.3g}", lambda res, c=column: _beats(res, c, base, state)),
            (f"{label} better than SE (L2({state}))", p_val < p_se, f"{p_val:.3g} vs {p_se:.3g}",
             lambda res, c=column: _beats_se(res, c, state)),
            (f"{label} reaches the paper's L2({state}) = {p_val:.3g}", None, f"{p_val:.3g}",
             lambda res, c=column, v=p_val: [x <= v for x in _by_seed(res, c, state).values()]),
        ]
        p_epochs = (paper.get("epochs") or {})
        if column in p_epochs and base in p_epochs:
            specs.append((f"{label} needs fewer target epochs than {labels.get(base, base)}",
                          p_epochs[column] < p_epochs[base], f"{p_epochs[column]} vs {p_epochs[base]}",
                          lambda res, c=column: _fewer_epochs(res, c, base)))
        for claim, finding, text, check in specs:
            counts = {}
            for profile, res in loaded.items():
                held = check(res)
                if finding is False:  # the paper says it does not hold: count the seeds that agree
                    held = [not h for h in held]
                counts[profile] = _count(held)
            rows.append({"column": column, "label": label, "claim": claim if finding is not False
                         else claim.replace(" better than ", " not better than ").replace(" fewer ", " not fewer "),
                         "paper": finding, "paper_text": text, "profiles": counts})
    return {"experiment": first["experiment"], "paper_experiment": name, "state": state, "baseline": base,
            "rows": rows}


def _beats(res: dict, column: str, base: str, state: str) -> list[bool]:
    mine, theirs = _by_seed(res, column, state), _by_seed(res, base, state)
    return [mine[s] < theirs[s] for s in mine if s in theirs]


def _beats_se(res: dict, column: str, state: str) -> list[bool]:
    se = _se_value(res, state)
    return [] if se is None else [v < se for v in _by_seed(res, column, state).values()]


def _fewer_epochs(res: dict, column: str, base: str) -> list[bool]:
    mine, theirs = _epochs_by_seed(res, column), _epochs_by_seed(res, base)
    return [mine[s] < theirs[s] for s in mine if s in theirs]


def markdown(claims: list[dict], profiles: list[str]) -> str:
    """One table per experiment: claim, the paper's numbers, and k/n seeds per profile (of
    ``profiles``, those the experiment was run in)."""
    out = []
    for exp in claims:
        present = [p for p in profiles if any(p in row["profiles"] for row in exp["rows"])] or profiles
        against = "" if exp.get("paper_experiment", exp["experiment"]) == exp["experiment"] else \
            f", against the paper's {exp['paper_experiment']}"
        out += [f"**{exp['experiment']}** (L2 in the release's form, our seeds vs the paper's single run{against})", "",
                "| claim (as the paper finds it) | paper | " + " | ".join(f"{p} profile: seeds where it holds"
                                                               for p in present) + " |",
                "|---|---|" + "---|" * len(present)]
        for row in exp["rows"]:
            cells = []
            for p in present:
                c = row["profiles"].get(p)
                cells.append(f"{c['k']}/{c['n']}" if c and c["n"] else "–")
            out.append(f"| {row['claim']} | {row['paper_text']} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)
