"""Independent review cases for atlasnn.solver.solve_bundle (flow map). Usage: python cases.py NAME [seed]"""
import json, os, sys, time
import numpy as np
from atlasnn.systems import BundleBox, expression_system, builtin_system
from atlasnn.solver import solve_bundle, FlowMap
from atlasnn.evaluation import reference_members

PI = np.pi
OUT = os.environ.get("OUT", "../../docs/benchmarks/flowmap_review")  # where each case's JSON goes
osc = lambda: builtin_system("nonlinear_oscillator")
def duffing():  # double well, separatrix at H = 0 (the saddle at the origin)
    return expression_system("p**2/2 - a*x**2/2 + b*x**4/4", ["x"], ["p"], params={"a": 1.0, "b": 1.0}, z0=[1.0, 0.0], name="dw")
def pend():
    return expression_system("p**2/2 - g*cos(q)", ["q"], ["p"], params={"g": 1.0}, z0=[1.0, 0.0], name="pend")
def osc2():
    return expression_system("p**2/2 + w*x**2/2 + lam*x**4/4", ["x"], ["p"], params={"w": 1.0, "lam": 1.0}, z0=[1.3, 1.0], name="osc2")
def hh():
    return builtin_system("henon_heiles")
def coupled():
    return expression_system("(p1**2+p2**2)/2 + (x1**2 + w*x2**2)/2 + k*(x1-x2)**2/2", ["x1", "x2"], ["p1", "p2"],
                             params={"w": 1.5, "k": 0.2}, z0=[1.0, 0.0, 0.0, 0.5], name="coupled")

CASES = {
    # name: (system factory, box, FlowMap)
    "osc_baseline": (osc, BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=4 * PI), FlowMap()),
    "osc_narrow": (osc, BundleBox.around([1.3, 1.0], 0.01, {"lam": (0.99, 1.01)}, T=4 * PI), FlowMap()),
    "osc_wide": (osc, BundleBox.around([1.3, 1.0], 0.5, {"lam": (0.0, 2.0)}, T=4 * PI), FlowMap()),
    "osc_longT_default_windows": (osc, BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=40 * PI), FlowMap()),
    "osc_longT_960_windows": (osc, BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=40 * PI), FlowMap(windows=960)),
    "osc_t0_shift": (osc, BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=1.0 + 4 * PI, t0=1.0), FlowMap()),
    "osc_two_params_pdeg2": (osc2, BundleBox.around([1.3, 1.0], 0.2, {"w": (0.8, 1.2), "lam": (0.5, 1.5)}, T=4 * PI), FlowMap(param_degree=2)),
    "duffing_inside_well": (duffing, BundleBox((0.9, -0.2), (1.2, 0.2), 4 * PI, {"b": (0.9, 1.1)}), FlowMap()),
    "duffing_straddle": (duffing, BundleBox((0.8, -0.5), (1.6, 0.5), 4 * PI, {"b": (0.9, 1.1)}), FlowMap()),
    "pend_libration": (pend, BundleBox((0.5, -0.5), (1.0, 0.5), 4 * PI, {"g": (0.8, 1.2)}), FlowMap()),
    "pend_near_separatrix": (pend, BundleBox((2.6, -0.3), (3.0, 0.3), 4 * PI, {"g": (0.9, 1.1)}), FlowMap()),
    "pend_rotating": (pend, BundleBox((-0.3, 2.6), (0.3, 3.0), 4 * PI, {"g": (0.8, 1.2)}), FlowMap()),
    "pend_straddle_rot": (pend, BundleBox((-0.3, 1.8), (0.3, 2.6), 4 * PI, {"g": (0.8, 1.2)}), FlowMap()),
    "hh_small": (hh, BundleBox.around([0.3, -0.3, 0.3, 0.15], 0.1, {"lam": (0.9, 1.1)}, T=10.0),
                 FlowMap(state_degree=4, time_degree=3, param_degree=1)),
    "coupled_small": (coupled, BundleBox.around([1.0, 0.0, 0.0, 0.5], 0.1, {"k": (0.1, 0.3)}, T=4 * PI),
                      FlowMap(state_degree=4, time_degree=3, param_degree=1)),
}

def run(name, seed=0, members=200, test_seed=12345):
    make, box, method = CASES[name]
    system = make()
    t_start = time.perf_counter()
    b = solve_bundle(system, box, method, seed=seed)
    solve_s = time.perf_counter() - t_start
    z0, lam = box.draw(np.random.default_rng(test_seed), members)
    t = np.linspace(box.t0, box.T, 101)
    ref = reference_members(system, box, z0, lam, t)
    with np.errstate(all="ignore"):
        zh = b(t, z0, lam)
    err = np.abs(zh - ref).max(axis=2)
    per_member = np.where(np.isfinite(err), err, np.inf).max(axis=1)
    exact_t0 = float(np.abs(zh[:, 0] - z0).max())
    out = {"case": name, "seed": seed, "method": method.__dict__, "box": box.describe(), "solve_s": solve_s,
           "info_seconds": b.info["seconds"], "unknowns": b.info["unknowns"],
           "worst": float(per_member.max()), "median": float(np.median(per_member)),
           "p90": float(np.quantile(per_member, 0.9)), "err_at_T_median": float(np.median(err[:, -1])),
           "held_out_residual_rms": b.info["held_out_residual_rms"], "held_out_residual_max": b.info["held_out_residual_max"],
           "residual_rms": b.info["residual_rms"], "region_contains_the_members": b.info["region_contains_the_members"],
           "final_region": b.info["fits"][-1]["region"], "n_fits": len(b.info["fits"]),
           "exact_at_t0": exact_t0, "ref_span": [ref.reshape(-1, ref.shape[-1]).min(0).tolist(), ref.reshape(-1, ref.shape[-1]).max(0).tolist()]}
    print(json.dumps(out))
    with open(f"{OUT}/{name}_s{seed}.json", "w") as f:
        json.dump(out, f, indent=1)
    return out, b

if __name__ == "__main__":
    run(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 0)
