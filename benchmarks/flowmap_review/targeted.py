"""Targeted members: the double-well separatrix, the wide oscillator box's worst members, the pendulum's region growth."""
import sys, numpy as np
from cases import CASES
from atlasnn.solver import solve_bundle
from atlasnn.evaluation import reference_members
which = sys.argv[1]
if which == "duffing_sep":
    make, box, method = CASES["duffing_straddle"]; sys_ = make()
    b = solve_bundle(sys_, box, method, seed=0)
    rng = np.random.default_rng(1)
    bval = rng.uniform(0.9, 1.1, 60)
    eps = np.concatenate([np.zeros(20), rng.uniform(-1e-3, 1e-3, 20), rng.uniform(-3e-2, 3e-2, 20)])
    x0 = np.sqrt(2 / bval) * (1 + eps)  # H = -x²/2 + b x⁴/4 = 0 at x = sqrt(2/b)
    z0 = np.stack([x0, np.zeros_like(x0)], 1); lam = bval[:, None]
    t = np.linspace(0, box.T, 101)
    ref = reference_members(sys_, box, z0, lam, t)
    err = np.abs(b(t, z0, lam) - ref).max(axis=(1, 2))
    for name, sl in (("on separatrix (H=0)", slice(0, 20)), ("|dx/x|<1e-3", slice(20, 40)), ("|dx/x|<3e-2", slice(40, 60))):
        print(f"{name}: worst {err[sl].max():.2e} median {np.median(err[sl]):.2e}")
    print("info:", b.info["held_out_residual_rms"], b.info["region_contains_the_members"], "estimated", b.info["estimated_error"], "gap", b.info["composition_gap"])
elif which == "osc_wide":
    make, box, method = CASES["osc_wide"]; sys_ = make()
    b = solve_bundle(sys_, box, method, seed=0)
    z0, lam = box.draw(np.random.default_rng(12345), 200)
    t = np.linspace(0, box.T, 101)
    ref = reference_members(sys_, box, z0, lam, t)
    err = np.abs(b(t, z0, lam) - ref).max(axis=2)
    pm = err.max(1); H = z0[:, 1]**2/2 + z0[:, 0]**2/2 + lam[:, 0]*z0[:, 0]**4/4
    for i in np.argsort(pm)[::-1][:5]:
        print(f"member z0={z0[i].round(3)} lam={lam[i,0]:.3f} H={H[i]:.2f} err {pm[i]:.2e} (err at t=1: {err[i, 8]:.1e})")
    print("H range of members", H.min(), H.max())
    # the corner of highest energy
    zc = np.array([[1.95, 1.5]]); lc = np.array([[2.0]])
    rc = reference_members(sys_, box, zc, lc, t); print("corner (1.95,1.5,lam=2) err", np.abs(b(t, zc, lc) - rc).max())
    for s in (1, 2):
        b2 = solve_bundle(sys_, box, method, seed=s)
        e2 = np.abs(b2(t, z0, lam) - ref).max(axis=(1, 2))
        print(f"seed {s}: {b2.info['seconds']:.1f}s worst {e2.max():.2e} median {np.median(e2):.2e} hrms {b2.info['held_out_residual_rms']:.2e} contained {b2.info['region_contains_the_members']}")
elif which == "pend":
    make, box, method = CASES[sys.argv[2]]; sys_ = make()
    try:
        solve_bundle(sys_, box, method, seed=0, progress=lambda l: print(l) if "flow map" in l or "Gauss–Newton 1:" in l else None)
    except Exception as e:
        print(type(e).__name__, e)
