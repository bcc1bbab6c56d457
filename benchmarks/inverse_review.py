"""An independent check of fit_collocation and fit_shooting(segments="auto") on cases their authors
did not tune on (written by a reviewer, run as written): coupled oscillators seen through one
coordinate, Hénon–Heiles with escaping orbits in the bounds, a noisy sparse pendulum, very wide
bounds with guesses at the bounds, a Morse oscillator with two unknowns, a quartic oscillator
observed only on [5, 15]. Five guesses per case, a 90 s alarm per fit; one JSON line per fit.

    python -m benchmarks.inverse_review all      (or case names; about 7 minutes)

Writes docs/benchmarks/inverse_review/results_<case>.jsonl."""
import json, signal, sys, time, traceback
import numpy as np
from atlasnn.errors import AtlasError
from atlasnn.inverse import fit_collocation, fit_shooting, synthetic_observations
from atlasnn.observations import Unknown
from atlasnn.systems import expression_system

OUT = "docs/benchmarks/inverse_review"
FIT_LIMIT = 90  # seconds, alarm per fit


def spread(lo, hi, edge=0.02):
    w = hi - lo
    return [lo + edge * w, lo + 0.25 * w, lo + 0.5 * w, lo + 0.75 * w, hi - edge * w]


def cases():
    C = {}
    # 1 coupled oscillators + quartic, only x1 observed, unknown k
    s = expression_system("(p1**2+p2**2)/2 + (x1**2+x2**2)/2 + k*x1*x2 + 0.1*(x1**4+x2**4)", ["x1", "x2"],
                          ["p1", "p2"], params={"k": 0.3}, z0=[1.0, 0.0, 0.0, 0.0], name="coupled")
    C["coupled-k"] = dict(system=s, names=["x1"], first=0.0, T=30.0, n=50, noise=0.01, t0=0.0,
                          unknowns=[("k", 0.3, 0.0, 0.9)], guesses=[[g] for g in spread(0.0, 0.9)])
    # 2 Henon-Heiles with unknown lambda (orbits escape for large lambda)
    s = expression_system("(px**2+py**2)/2 + (x**2+y**2)/2 + lam*(x**2*y - y**3/3)", ["x", "y"], ["px", "py"],
                          params={"lam": 1.0}, z0=[0.1, -0.2, 0.3, 0.15], name="henon_heiles")
    C["henon-heiles-lam"] = dict(system=s, names=["x", "y"], first=0.0, T=25.0, n=60, noise=0.01, t0=0.0,
                                 unknowns=[("lam", 1.0, 0.2, 3.0)], guesses=[[g] for g in spread(0.2, 3.0)])
    # 3 pendulum, 5% noise, 13 sparse observations, large amplitude
    s = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], params={"g": 1.0}, z0=[1.5, 0.0], name="pendulum")
    C["pendulum-noisy-sparse"] = dict(system=s, names=["x"], first=0.0, T=15.0, n=13, noise=0.05, t0=0.0,
                                      unknowns=[("g", 1.0, 0.3, 3.0)], guesses=[[g] for g in spread(0.3, 3.0)])
    # 4 pendulum, wide bounds, guesses at the bounds exactly
    s2 = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], params={"g": 2.0}, z0=[1.0, 0.0], name="pendulum2")
    C["pendulum-wide-bounds"] = dict(system=s2, names=["x"], first=0.0, T=20.0, n=40, noise=0.01, t0=0.0,
                                     unknowns=[("g", 2.0, 0.01, 100.0)],
                                     guesses=[[0.01], [0.05], [10.0], [50.0], [100.0]])
    # 5 Morse oscillator, two unknowns (D, z0.p), x observed
    s = expression_system("p**2/2 + D*(1 - exp(-x))**2", ["x"], ["p"], params={"D": 1.0}, z0=[0.5, 0.3],
                          name="morse")
    C["morse-D-p0"] = dict(system=s, names=["x"], first=0.0, T=15.0, n=40, noise=0.01, t0=0.0,
                           unknowns=[("D", 1.0, 0.3, 3.0), ("z0.p", 0.3, -1.0, 1.0)],
                           guesses=[[0.35, -0.95], [2.95, 0.95], [0.35, 0.95], [2.95, -0.95], [1.65, 0.0]])
    # 6 pure quartic oscillator observed on [5, 15] only, t0 = 0
    s = expression_system("p**2/2 + a*x**4/4", ["x"], ["p"], params={"a": 1.0}, z0=[1.0, 0.0], name="quartic")
    C["quartic-late-data"] = dict(system=s, names=["x"], first=5.0, T=15.0, n=30, noise=0.01, t0=0.0,
                                  unknowns=[("a", 1.0, 0.2, 5.0)], guesses=[[g] for g in spread(0.2, 5.0)])
    return C


class Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise Timeout(f"fit exceeded {FIT_LIMIT}s")


def run(name, c):
    system = c["system"]
    times = np.sort(np.random.default_rng(7).uniform(c["first"], c["T"], c["n"]))
    obs = synthetic_observations(system, system.initial_state(), times, c["names"], c["noise"], 11)
    truth = np.array([u[1] for u in c["unknowns"]])
    t = time.perf_counter()
    ref = fit_shooting(system, obs, [Unknown(*u) for u in c["unknowns"]], t0=c["t0"])
    ref_row = dict(case=name, kind="reference", estimate=ref.estimate.tolist(), std=ref.std.tolist(),
                   trusted=ref.trusted, notes=ref.notes, residual_rms=ref.residual_rms, truth=truth.tolist(),
                   seconds=time.perf_counter() - t)
    rows = [ref_row]
    print(json.dumps(ref_row), flush=True)
    methods = {"collocation": lambda u: fit_collocation(system, obs, u, t0=c["t0"]),
               "shooting-auto": lambda u: fit_shooting(system, obs, u, t0=c["t0"], segments="auto")}
    for g in c["guesses"]:
        unk = [Unknown(u[0], float(v), u[2], u[3]) for u, v in zip(c["unknowns"], g)]
        for m, f in methods.items():
            row = dict(case=name, kind=m, guess=list(map(float, g)))
            t = time.perf_counter()
            signal.alarm(FIT_LIMIT)
            try:
                fit = f(unk)
                signal.alarm(0)
                est, std = fit.estimate, fit.std
                dev = np.abs(est - ref.estimate)
                row.update(estimate=est.tolist(), std=std.tolist(), trusted=bool(fit.trusted), notes=fit.notes,
                           residual_rms=fit.residual_rms, method=fit.method,
                           reached=bool(np.all(dev <= 0.5 * ref.std)),
                           confident_wrong=bool(fit.trusted and np.any(dev > 4 * ref.std)),
                           cw_own_std=bool(fit.trusted and np.any(dev > 4 * std)),
                           cw_truth=bool(fit.trusted and np.any(np.abs(est - truth) > 4 * np.maximum(std, ref.std))),
                           dev_sigmas=(dev / ref.std).tolist(),
                           search={k: v for k, v in fit.search.items() if k in ("windows", "lm_steps",
                                   "collocation_estimate", "polish", "polish_moved_sigmas")},
                           segments=fit.segments, seconds=fit.wall_time)
            except AtlasError as exc:
                signal.alarm(0)
                row.update(refused=f"{type(exc).__name__}: {exc}", seconds=time.perf_counter() - t)
            except Exception as exc:  # noqa
                signal.alarm(0)
                row.update(exception=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc(),
                           seconds=time.perf_counter() - t)
            rows.append(row)
            print(json.dumps(row), flush=True)
    with open(f"{OUT}/results_{name}.jsonl", "w") as fh:
        for r in rows:
            fh.write(json.dumps(r) + "\n")


if __name__ == "__main__":
    signal.signal(signal.SIGALRM, _alarm)
    C = cases()
    names = list(C) if sys.argv[1:] in ([], ["all"]) else sys.argv[1:]
    for n in names:
        run(n, C[n])
