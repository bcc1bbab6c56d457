"""Amortised cost of a bundle: seconds per answered trajectory after N queries, bundle against a
classical integrator vectorised over the same N members.

The problem is the bundle's own box (the built-in experiment's: the nonlinear oscillator
H = p²/2 + x²/2 + lam·x⁴/4 on [0, 4π], z0 within ±20 % of (1.3, 1.0), lam in [0.5, 1.5]). Three
kinds of query, each answered for N ∈ {10², 10³, 10⁴, 10⁵} members drawn from the box:

- dense: the state at 100 output times on [t0, T];
- far: the state at T only (the bundle evaluates its windows' chain at one time; an integrator
  still steps the whole way);
- sensitivity: the state and ∂z/∂λ at the 100 times (what a least-squares fit of λ needs); the
  bundle by forward-mode autodiff (``BundleSolution.sensitivities``, which also gives ∂ẑ/∂z0),
  the integrators by central differences in each varying parameter (2 extra solves per parameter,
  run in the same vectorised call as the base solve).

Classical side: Yoshida-4 and Störmer–Verlet in float64 (``atlasnn.evaluation.yoshida4_members``,
``verlet_members``) at several steps per unit time; wall seconds after compiling (best of 3),
force evaluations per member, and the worst and median over 200 held-out members of each
member's max |error| against DOP853 at 1e-12 (``reference_members``); DOP853 itself, per member
(SciPy, one member after another), at rtol = atol = 1e-8 and 1e-12. The sensitivity reference is
the central difference (δ = 1e-4) of the DOP853 references, good to about 1e-8.

Network side (or a float64 flow map, ``models/flowmap_seedS.npz``, whose sensitivities are central
differences like the integrators'): the bundle's evaluation time for the same queries (after compiling, best of 3), its
errors on the same held-out members, its training time (the run's results.json, or the training
done here). Amortised per trajectory: (training + eval(N)) / N against classical(N) / N, the
classical setting being the cheapest whose worst error is at most the bundle's worst error (the
"matched accuracy"). The crossover is the N beyond which the bundle is cheaper: measured on the N
grid, and extrapolated as training / (classical − bundle evaluation) per member, which exists only
if a bundle evaluation costs less per member than the matched classical solve.

    taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false \\
        python -m benchmarks.bundle_cost --run DIR [--seed 0] \\
        [--out docs/benchmarks/bundle_cost.json] [--figure docs/figures/bundle_cost]

(``--train`` instead of ``--run DIR`` trains a small bundle here first: 4 windows × 1 000 Adam
epochs + 50 LM steps, width 32.) One core, pinned (the issue's numbers are for one core); about
5 minutes after the training.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import machine_info

SIZES = (100, 1000, 10_000, 100_000)
N_TIMES = 100
HELD_OUT = 200
HELD_OUT_SEED = 2718
YOSHIDA_SPU = (1, 2, 4, 8, 16, 32, 64)
VERLET_SPU = (4, 8, 16, 32, 64, 128, 256, 512)
DOP853_TOLS = (1e-8, 1e-12)
DOP853_MEMBERS = 20
FD_STEP = 1e-4
SENS_CHUNK = 2000
TRAIN = {"windows": 4, "epochs": 1000, "lm_steps": 50, "lm_points": 512, "width": 32}
CASES = ("dense", "far", "sensitivity")
ONE_CORE = ("timings on one core: run under `taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false`; "
            "see machine.cores_available")


def best_of(fn, repeats: int = 3) -> float:
    """Seconds of the fastest of ``repeats`` calls, after one untimed call (compiling)."""
    fn()
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return min(out)


def member_errors(answer: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per member: max over times and components of |answer − ref| (inf where not finite)."""
    err = np.abs(np.asarray(answer, np.float64) - ref).reshape(ref.shape[0], -1).max(axis=1)
    return np.where(np.isfinite(err), err, np.inf)


def summary(err: np.ndarray) -> dict:
    return {"worst": float(err.max()), "median": float(np.median(err))}


# ------------------------------------------------------------------------------ the bundle
def load_run(run_dir: str, seed: int):
    """A network bundle (models/bundle_seedS.npz) or a float64 flow map (models/flowmap_seedS.npz)."""
    from atlasnn import load

    results, model = Path(run_dir) / "results.json", Path(run_dir) / "models" / f"bundle_seed{seed}.npz"
    flowmap = Path(run_dir) / "models" / f"flowmap_seed{seed}.npz"
    if flowmap.is_file():
        model = flowmap
    for p in (results, model):
        if not p.is_file():
            raise SystemExit(f"bundle_cost: {p} is missing (is {run_dir} a finished bundle run?)")
    record = json.loads(results.read_text(encoding="utf-8")).get("seeds", {}).get(str(seed))
    if not record or "train_time" not in record:
        raise SystemExit(f"bundle_cost: {results} has no train_time for seed {seed}")
    loaded = load(model)  # a flow map or a trained bundle, by the file's kind
    return loaded, float(record["train_time"]), {"source": str(run_dir), "seed": seed,
                                                              "recorded_test": record.get("test")}


def train_here(seed: int):
    from atlasnn.systems import BundleBox, builtin_system
    from atlasnn.training import BundleTrainConfig, train_bundle

    system = builtin_system("nonlinear_oscillator")
    box = BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=4 * np.pi)
    cfg = {k: v for k, v in TRAIN.items() if k != "width"}
    out = train_bundle(system, box, BundleTrainConfig(**cfg), width=TRAIN["width"], seed=seed)
    print(f"trained a bundle in {out.train_time:.1f} s (+ {out.compile_time:.1f} s compiling)")
    return out.solution, float(out.train_time), {"source": "trained here", "seed": seed, "settings": TRAIN,
                                                 "compile_time": float(out.compile_time)}


def is_flowmap(sol) -> bool:
    from atlasnn.solutions import FlowMapBundle

    return isinstance(sol, FlowMapBundle)


def bundle_sensitivity(sol, t, z0, lam) -> np.ndarray:
    """ẑ and ∂ẑ/∂λ (N, T, 2d, P) in member chunks of equal size (one compilation); a flow map by
    central differences, as the integrators (one evaluation of 2P + 1 stacked member sets)."""
    n = z0.shape[0]
    if is_flowmap(sol):
        n_p = lam.shape[1]
        shifted = [lam]
        for j in range(n_p):
            step = np.zeros_like(lam)
            step[:, j] = FD_STEP
            shifted += [lam + step, lam - step]
        z = sol(t, np.concatenate([z0] * (2 * n_p + 1)), np.concatenate(shifted))
        z = z.reshape(2 * n_p + 1, n, *z.shape[1:])
        return np.stack([(z[1 + 2 * j] - z[2 + 2 * j]) / (2 * FD_STEP) for j in range(n_p)], axis=-1)
    chunk = min(SENS_CHUNK, n)
    pad = -(-n // chunk) * chunk - n
    zp, lp = np.concatenate([z0, np.repeat(z0[-1:], pad, 0)]), np.concatenate([lam, np.repeat(lam[-1:], pad, 0)])
    parts = [sol.sensitivities(t, zp[i : i + chunk], lp[i : i + chunk])[1] for i in range(0, n + pad, chunk)]
    sol(t, z0, lam)  # a fit needs the states as well
    return np.concatenate(parts)[:n]


# --------------------------------------------------------------------------- the problem
class Problem:
    """The bundle's box and system, the held-out members and their references."""

    def __init__(self, sol):
        from atlasnn.evaluation import reference_members
        from atlasnn.systems import builtin_system

        self.sol, self.box = sol, sol.box
        system = getattr(sol, "system", None)
        self.system = system if system is not None else builtin_system("nonlinear_oscillator")
        self.t = {"dense": np.linspace(self.box.t0, self.box.T, N_TIMES), "far": np.array([self.box.T])}
        self.t["sensitivity"] = self.t["dense"]
        self.z0, self.lam = self.box.draw(np.random.default_rng(HELD_OUT_SEED), HELD_OUT)
        start = time.perf_counter()
        ref = reference_members(self.system, self.box, self.z0, self.lam, self.t["dense"])
        self.ref = {"dense": ref, "far": ref[:, -1:]}
        if self.box.params:
            derivs = []
            for j in range(len(self.box.params)):
                step = np.zeros_like(self.lam)
                step[:, j] = FD_STEP
                up = reference_members(self.system, self.box, self.z0, self.lam + step, self.t["dense"])
                down = reference_members(self.system, self.box, self.z0, self.lam - step, self.t["dense"])
                derivs.append((up - down) / (2 * FD_STEP))
            self.ref["sensitivity"] = np.stack(derivs, axis=-1)
        self.reference_seconds = time.perf_counter() - start

    def cases(self):
        return [c for c in CASES if c in self.ref]

    def draw(self, n: int):
        return self.box.draw(np.random.default_rng(n), n)

    # ---------------------------------------------------------------- answers per case
    def classical(self, case: str, fn, z0, lam, spu):
        """(answer compared with the reference, force evaluations per member)."""
        t = self.t[case]
        if case != "sensitivity":
            run = fn(self.system, self.box, z0, lam, t, spu)
            return run.z, run.force_evaluations
        n, n_p = lam.shape
        shifted = [lam]
        for j in range(n_p):
            step = np.zeros_like(lam)
            step[:, j] = FD_STEP
            shifted += [lam + step, lam - step]
        run = fn(self.system, self.box, np.concatenate([z0] * (2 * n_p + 1)), np.concatenate(shifted), t, spu)
        z = run.z.reshape(2 * n_p + 1, n, *run.z.shape[1:])
        deriv = np.stack([(z[1 + 2 * j] - z[2 + 2 * j]) / (2 * FD_STEP) for j in range(n_p)], axis=-1)
        return deriv, run.force_evaluations * (2 * n_p + 1)

    def bundle(self, case: str, z0, lam):
        if case == "sensitivity":
            return bundle_sensitivity(self.sol, self.t[case], z0, lam)
        return self.sol(self.t[case], z0, lam)


# ---------------------------------------------------------------------------- measuring
def classical_rows(pb: Problem, case: str, sizes) -> list[dict]:
    from atlasnn.evaluation import verlet_members, yoshida4_members

    rows = []
    for method, fn, spus in (("yoshida4", yoshida4_members, YOSHIDA_SPU), ("verlet", verlet_members, VERLET_SPU)):
        seen = set()
        for spu in spus:
            answer, evals = pb.classical(case, fn, pb.z0, pb.lam, spu)
            if evals in seen:  # the output times already force this many steps
                continue
            seen.add(evals)
            row = {"method": method, "steps_per_unit": spu, "force_evaluations": evals,
                   **summary(member_errors(answer, pb.ref[case])), "seconds": {}}
            for n in sizes:
                z0, lam = pb.draw(n)
                row["seconds"][str(n)] = best_of(lambda fn=fn, z0=z0, lam=lam, spu=spu: pb.classical(case, fn, z0, lam, spu))
            print(f"  {case} {method} {spu:>4}/unit: worst {row['worst']:.2e}, median {row['median']:.2e}, "
                  f"{row['seconds'][str(sizes[-1])]:.3f} s for {sizes[-1]} members")
            rows.append(row)
    return rows


def dop853_rows(pb: Problem, case: str) -> list[dict]:
    from atlasnn.evaluation import reference_members

    if case == "sensitivity":
        return []
    z0, lam, t = pb.z0[:DOP853_MEMBERS], pb.lam[:DOP853_MEMBERS], pb.t[case]
    rows = []
    for tol in DOP853_TOLS:
        def solve(tol=tol):
            return reference_members(pb.system, pb.box, z0, lam, t, rtol=tol, atol=tol)

        seconds = best_of(solve)
        err = member_errors(solve(), pb.ref[case][:DOP853_MEMBERS])
        rows.append({"method": "dop853", "tol": tol, "members": DOP853_MEMBERS,
                     "seconds_per_member": seconds / DOP853_MEMBERS, **summary(err),
                     "note": "the reference itself (error 0 by construction)" if tol == 1e-12 else None})
    return rows


def bundle_row(pb: Problem, case: str, sizes) -> dict:
    row = {**summary(member_errors(pb.bundle(case, pb.z0, pb.lam), pb.ref[case])), "seconds": {}}
    for n in sizes:
        z0, lam = pb.draw(n)
        row["seconds"][str(n)] = best_of(lambda z0=z0, lam=lam: pb.bundle(case, z0, lam))
    print(f"  {case} bundle: worst {row['worst']:.2e}, median {row['median']:.2e}, "
          f"{row['seconds'][str(sizes[-1])]:.3f} s for {sizes[-1]} members")
    return row


def amortise(case: dict, train: float, sizes) -> None:
    """Adds the matched classical setting, the cost per trajectory per N and the crossover."""
    b = case["bundle"]
    ok = [r for r in case["classical"] if r["worst"] <= b["worst"]]
    note = None
    if not ok:  # nothing classical is as accurate: compare with the most accurate setting
        ok = [min(case["classical"], key=lambda r: r["worst"])]
        note = "no classical setting reaches the bundle's worst error; compared with the most accurate one"
    rows, crossing = [], None
    for n in sizes:
        best = min(ok, key=lambda r: r["seconds"][str(n)])
        per = {"N": n, "bundle": (train + b["seconds"][str(n)]) / n, "bundle_eval_only": b["seconds"][str(n)] / n,
               "classical": best["seconds"][str(n)] / n, "classical_setting": f"{best['method']} {best['steps_per_unit']}/unit"}
        dop = [r for r in case["dop853"] if r["worst"] <= b["worst"]]
        per["dop853"] = min(r["seconds_per_member"] for r in dop) if dop else None
        rows.append(per)
        if crossing is None and per["bundle"] <= per["classical"]:
            crossing = n
    last = rows[-1]
    gap = last["classical"] - last["bundle_eval_only"]
    case.update(matched_note=note, amortised=rows, crossover_measured_N=crossing,
                crossover_extrapolated_N=train / gap if gap > 0 else None,
                crossover_note=(f"bundle evaluation {last['bundle_eval_only'] * 1e6:.3g} µs per member "
                                f"{'<' if gap > 0 else '≥'} matched classical solve {last['classical'] * 1e6:.3g} µs "
                                f"per member at N = {last['N']}: "
                                + (f"training amortised after N ≈ {train / gap:.3g} queries" if gap > 0
                                   else "no N amortises the training (no crossover)")))


# ------------------------------------------------------------------------------- figure
def figure(result: dict, stem: str) -> list[str]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cases = result["cases"]
    fig = Figure(figsize=(4.8 * len(cases), 5.4), constrained_layout=True)
    FigureCanvasAgg(fig)
    titles = {"dense": f"{N_TIMES} output times", "far": "one time, T", "sensitivity": f"z and ∂z/∂λ at {N_TIMES} times"}
    train = result["bundle"]["train_time"]
    for i, (name, case) in enumerate(cases.items()):
        ax = fig.add_subplot(1, len(cases), i + 1)
        rows = case["amortised"]
        n = np.array([r["N"] for r in rows], float)
        grid = np.logspace(np.log10(n[0]) - 1, 8, 200)
        ax.plot(n, [r["bundle"] for r in rows], "o", color="C0", label="bundle: (training + eval) / N")
        ax.plot(grid, train / grid + rows[-1]["bundle_eval_only"], "--", color="C0", lw=1,
                label=f"bundle extrapolated: training / N + eval per member at N = {rows[-1]['N']}")
        ax.plot(n, [r["bundle_eval_only"] for r in rows], ":", color="C0", label="bundle evaluation only")
        ax.plot(n, [r["classical"] for r in rows], "s-", color="C1",
                label=f"classical, matched ({rows[-1]['classical_setting']})")
        ax.plot(grid, np.full_like(grid, rows[-1]["classical"]), "--", color="C1", lw=1,
                label=f"classical extrapolated: per member at N = {rows[-1]['N']}")
        dop = [r["dop853"] for r in rows if r["dop853"] is not None]
        if dop:
            ax.axhline(dop[-1], color="C2", lw=1, label="DOP853, one member at a time")
        if case["crossover_extrapolated_N"]:
            ax.axvline(case["crossover_extrapolated_N"], color="k", lw=0.8, ls="-.",
                       label=f"crossover N ≈ {case['crossover_extrapolated_N']:.2g}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("N (members queried)")
        ax.set_ylabel("seconds per answered trajectory")
        ax.set_title(f"{titles[name]}; bundle worst error {case['bundle']['worst']:.1e}", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.16))
    fig.suptitle("Bundle vs vectorised classical integrators, amortised cost (one core)", fontsize=10)
    Path(stem).parent.mkdir(parents=True, exist_ok=True)
    paths = []
    for ext in ("png", "pdf"):
        fig.savefig(f"{stem}.{ext}", dpi=150)
        paths.append(f"{stem}.{ext}")
    return paths


# --------------------------------------------------------------------------------- main
def finite(obj):
    """The result with non-finite floats as None (strict JSON)."""
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def measure(sol, train: float, source: dict, sizes) -> dict:
    pb = Problem(sol)
    print(f"references for {HELD_OUT} held-out members: {pb.reference_seconds:.1f} s")
    if is_flowmap(sol):
        kind = {"kind": "float64 flow map", "basis": {f: getattr(sol.basis, f) for f in
                                                     ("time_degree", "state_degree", "param_degree", "h")},
                "unknowns": sol.info.get("unknowns"), "dtype": "float64", "windows": sol.windows}
    else:
        first = sol.windows[0]
        kind = {"kind": "network", "architecture": first.architecture(), "dtype": str(first.weights[0].dtype),
                "windows": len(sol.windows)}
    result = {
        "problem": {"system": pb.system.describe(), "box": pb.box.describe(), "output_times": N_TIMES,
                    "held_out_members": HELD_OUT, "held_out_seed": HELD_OUT_SEED, "sizes": list(sizes),
                    "reference": "DOP853 rtol = atol = 1e-12; ∂z/∂λ by central differences of it, δ = 1e-4",
                    "classical_sensitivity": "central differences, δ = 1e-4, 2 extra solves per parameter "
                                             "in the same vectorised call; force evaluations include all three"},
        "bundle": {**source, "train_time": train, **kind},
        "cases": {},
    }
    for case in pb.cases():
        print(f"case {case}:")
        entry = {"bundle": bundle_row(pb, case, sizes), "classical": classical_rows(pb, case, sizes),
                 "dop853": dop853_rows(pb, case)}
        amortise(entry, train, sizes)
        print(f"  {entry['crossover_note']}")
        result["cases"][case] = entry
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bundle_cost", description=__doc__.split("\n")[0])
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--run", metavar="DIR", help="a finished bundle run (results.json, models/bundle_seedS.npz)")
    src.add_argument("--train", action="store_true", help="train a small bundle here first")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sizes", nargs="+", type=int, default=list(SIZES), help="numbers of members N")
    ap.add_argument("--out", default="docs/benchmarks/bundle_cost.json")
    ap.add_argument("--figure", default="docs/figures/bundle_cost", help="figure path without extension")
    args = ap.parse_args(argv)
    sizes = sorted(set(args.sizes))
    if not sizes or sizes[0] < 1:
        raise SystemExit("bundle_cost: --sizes must be positive integers")
    sol, train, source = load_run(args.run, args.seed) if args.run else train_here(args.seed)
    result = measure(sol, train, source, sizes)
    argv_text = " ".join(argv if argv is not None else sys.argv[1:])
    result.update(machine=machine_info(), timing=ONE_CORE, command=f"python -m benchmarks.bundle_cost {argv_text}",
                  pinned_command=f"taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false "
                                 f"python -m benchmarks.bundle_cost {argv_text}")
    if args.figure:
        result["figure"] = figure(result, args.figure)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(finite(result), indent=1, ensure_ascii=False), encoding="utf-8")
    print(f"wrote {args.out}" + (f" and {', '.join(result['figure'])}" if args.figure else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
