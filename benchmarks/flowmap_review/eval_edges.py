"""Bad inputs and edge cases for solve_bundle / FlowMapBundle. Prints the exception type and first line."""
import traceback, numpy as np
from atlasnn.systems import BundleBox, builtin_system
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

box = BundleBox((1.2, 0.9), (1.4, 1.1), 4 * PI, {"lam": (0.5, 1.5)})
b = attempt("small oscillator map", lambda: solve_bundle(osc, box, FlowMap()))
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
