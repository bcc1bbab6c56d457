"""Bad inputs and edge cases for solve_bundle / FlowMapBundle. Prints the exception type and first line."""
import traceback, numpy as np
from atlasnn.systems import BundleBox, builtin_system, expression_system
from atlasnn.solver import solve_bundle, FlowMap
PI = np.pi
osc = builtin_system("nonlinear_oscillator")
small = FlowMap(windows=8, state_degree=3, time_degree=2, param_degree=1)

def attempt(label, fn):
    try:
        r = fn()
        print(f"[{label}] NO ERROR -> {type(r).__name__}", (r.info.get('held_out_residual_rms'), r.info.get('region_contains_the_members')) if hasattr(r, 'info') else r if np.ndim(r)==0 else np.shape(r))
        return r
    except Exception as e:
        traceback.format_exc()  # (a traceback is what a one-line error must not need)
        mod = type(e).__module__
        msg = str(e)
        print(f"[{label}] {mod}.{type(e).__name__}: lines={msg.count(chr(10))+1}: {msg[:300]!r}")

attempt("zero-width box (z0 and lam fixed)", lambda: solve_bundle(osc, BundleBox((1.3, 1.0), (1.3, 1.0), 4 * PI, {"lam": (1.0, 1.0)}), small))
attempt("zero-width box, no params", lambda: solve_bundle(osc, BundleBox((1.3, 1.0), (1.3, 1.0), 4 * PI, {}), small))
attempt("T < t0", lambda: solve_bundle(osc, BundleBox((1.2, 0.9), (1.4, 1.1), 1.0, {"lam": (0.5, 1.5)}, t0=2.0), small))
attempt("T == t0", lambda: solve_bundle(osc, BundleBox((1.2, 0.9), (1.4, 1.1), 1.0, {"lam": (0.5, 1.5)}, t0=1.0), small))
attempt("low > high", lambda: solve_bundle(osc, BundleBox((1.4, 1.1), (1.2, 0.9), 4 * PI, {"lam": (0.5, 1.5)}), small))
attempt("lam range reversed", lambda: solve_bundle(osc, BundleBox((1.2, 0.9), (1.4, 1.1), 4 * PI, {"lam": (1.5, 0.5)}), small))
attempt("NaN in box", lambda: solve_bundle(osc, BundleBox((1.2, float('nan')), (1.4, 1.1), 4 * PI, {"lam": (0.5, 1.5)}), small))
attempt("param not in system", lambda: solve_bundle(osc, BundleBox((1.2, 0.9), (1.4, 1.1), 4 * PI, {"g": (0.5, 1.5)}), small))
attempt("wrong state dim", lambda: solve_bundle(osc, BundleBox((1.2, 0.9, 0.0, 0.0), (1.4, 1.1, 0.1, 0.1), 4 * PI, {"lam": (0.5, 1.5)}), small))
attempt("method not FlowMap", lambda: solve_bundle(osc, BundleBox((1.2, 0.9), (1.4, 1.1), 4 * PI, {"lam": (0.5, 1.5)}), "flowmap"))
attempt("FlowMap(windows=0)", lambda: FlowMap(windows=0))
attempt("FlowMap(state_degree=2.5)", lambda: FlowMap(state_degree=2.5))
attempt("FlowMap(oversampling=0.5)", lambda: FlowMap(oversampling=0.5))
attempt("FlowMap(oversampling=1.0) (underdetermined-ish)", lambda: FlowMap(oversampling=1.0))
hh = builtin_system("henon_heiles")
attempt("HH default FlowMap (max_unknowns)", lambda: solve_bundle(hh, BundleBox.around([0.3, -0.3, 0.3, 0.15], 0.1, {"lam": (0.9, 1.1)}, T=10.0)))
attempt("HH just over max_unknowns", lambda: solve_bundle(hh, BundleBox.around([0.3, -0.3, 0.3, 0.15], 0.1, {"lam": (0.9, 1.1)}, T=10.0), FlowMap(state_degree=6, time_degree=3, param_degree=1)))
nonpar = expression_system("p**2/2 + x**2/2", ["x"], ["p"], z0=[1.0, 0.0], name="ho")
attempt("system with no params, box with lam", lambda: solve_bundle(nonpar, BundleBox((0.9, -0.1), (1.1, 0.1), 4 * PI, {"lam": (0.5, 1.5)}), small))
b = attempt("system with no params, box without params", lambda: solve_bundle(nonpar, BundleBox((0.9, -0.1), (1.1, 0.1), 4 * PI, {}), small))
if b is not None:
    attempt("  eval, lam=np.zeros((3,0))", lambda: b([0.0, 1.0], np.array([[1.0, 0.0]] * 3), np.zeros((3, 0))))
box = BundleBox((1.2, 0.9), (1.4, 1.1), 4 * PI, {"lam": (0.5, 1.5)})
b = attempt("small oscillator map", lambda: solve_bundle(osc, box, small))
z0 = np.array([[1.3, 1.0], [1.25, 0.95]]); lam = np.array([[1.0], [0.7]])
attempt("eval t < t0", lambda: b([-0.1, 1.0], z0, lam))
attempt("eval t > T", lambda: b([1.0, 4 * PI + 0.01], z0, lam))
attempt("eval t = T exactly", lambda: b([4 * PI], z0, lam))
attempt("eval t unsorted", lambda: b([3.0, 1.0], z0, lam))
attempt("eval t NaN", lambda: b([np.nan, 1.0], z0, lam))
attempt("eval lam wrong count", lambda: b([1.0], z0, np.array([[1.0]])))
attempt("eval z0 wrong dim", lambda: b([1.0], np.array([1.0, 2.0, 3.0]), lam[:1]))
attempt("eval z0 far outside region (x=10)", lambda: b([0.0, 1.0, 4 * PI], np.array([[10.0, 0.0]]), lam[:1]))
attempt("eval lam outside range (lam=5)", lambda: b([0.0, 4 * PI], z0[:1], np.array([[5.0]])))
r = b([0.0], z0, lam); print("exact at t0:", np.abs(r[:, 0] - z0).max())
r = b([], z0, lam); print("empty t:", r.shape)
# unsorted consistency
r1 = b([1.0, 3.0], z0, lam); r2 = b([3.0, 1.0], z0, lam); print("unsorted same values:", np.allclose(r1[:, ::-1], r2))
