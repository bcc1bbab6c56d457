"""The commands that solve one problem without training a network: ``atlasnn integrate`` (the
classical integrators against the reference) and ``atlasnn solve`` (the solver door)."""

from __future__ import annotations

from pathlib import Path

from atlasnn.errors import AtlasError

#: ``atlasnn solve --check``: the reference, DOP853 at its tightest, and the looser run whose
#: distance from it tells how far the reference itself can be trusted (the --help quotes them)
CHECK_TOLERANCES = {"rtol": 2.5e-14, "atol": 1e-14}
CHECK_LOOSER = {"rtol": 1e-13, "atol": 1e-13}


def _integrate_problem(args):
    """(system, z0, t0, T, steps) from --system/--T/--steps, or from a config file (its system,
    z0 and evaluation interval; --T and --steps still override)."""
    from atlasnn.experiments.config import load_config, parse_end_time
    from atlasnn.systems import builtin_system

    config = args.config_pos or args.config
    if args.config_pos and args.config and args.config_pos != args.config:
        raise AtlasError(f"two configs given ({args.config_pos} and --config {args.config}); give one")
    if config is None:
        system = builtin_system(args.system or "nonlinear_oscillator")
        T = parse_end_time("--T", args.T or "4*pi")
        return system, system.initial_state(), 0.0, T, args.steps or 199
    if args.system is not None:
        raise AtlasError(f"--system {args.system} and a config ({config}) both name a system; give one")
    cfg = load_config(config)
    stage = cfg.eval_stage
    system = cfg.system.build()
    z0 = system.initial_state(cfg.system.z0)
    T = stage.T if args.T is None else parse_end_time("--T", args.T)
    if T <= stage.t0:
        raise AtlasError(f"--T {args.T}: must be greater than the config's t0 = {stage.t0:g}")
    steps = args.steps or cfg.evaluation.se_steps or stage.train.n_points - 1
    return system, z0, stage.t0, T, steps


def cmd_integrate(args) -> int:
    import numpy as np

    from atlasnn.evaluation import INTEGRATORS, REFERENCE_DESCRIPTION, energy_drift, error_table, integrate, reference_solution
    from atlasnn.limits import check_integration_memory

    if args.steps is not None and args.steps < 1:
        raise AtlasError(f"--steps must be >= 1, got {args.steps}")
    system, z0, t0, T, steps = _integrate_problem(args)
    check_integration_memory(steps, 2 * system.dim, key="--steps", value=steps)
    print(f"{system.name}: z0 = {z0.tolist()}, [{t0:g}, {T:.4f}], {steps} steps; reference: {REFERENCE_DESCRIPTION}")
    E0 = float(system.energy64(z0))
    if not system.separable:
        print(f"skipping {', '.join(INTEGRATORS)}: they need a separable H = T(p) + V(q) and "
              f"{system.name!r} is not declared separable")
        t = np.linspace(t0, T, steps + 1)
        ref = reference_solution(system, z0, t)
        drift = energy_drift(system.energy64(ref), E0)
        state = ", ".join(f"{n} = {v:.6g}" for n, v in zip(system.state_names, ref[-1]))
        print(f"reference: energy drift {drift:.3e} on {steps + 1} points; at t = {T:.4f}: {state}")
        return 0
    print(f"{'method':18s}" + "".join(f"{'L2(' + n + ')':>12s}" for n in system.state_names) + f"{'max|err|':>12s}{'energy drift':>14s}")
    unstable, refs = [], {}
    for method in INTEGRATORS:
        with np.errstate(all="ignore"):
            t, z = integrate(method, system, z0, t0, T, steps)
            key = t.tobytes()  # every method has the same grid: solve the reference once
            ref = refs[key] = refs[key] if key in refs else reference_solution(system, z0, t)
            tab = error_table(t, z, ref, system.state_names)
            drift = energy_drift(system.energy64(z), E0)
        if not np.all(np.isfinite(z)):
            unstable.append(method)
        cells = "".join(f"{tab['components'][n]['l2_discrete']:12.3e}" for n in system.state_names)
        print(f"{method:18s}{cells}{tab['whole']['max_abs']:12.3e}{drift:14.3e}")
    print("L2 = sqrt(sum_i err_i^2) on each method's own grid (the release's tabulated form)")
    if unstable:
        print(f"nan: {', '.join(unstable)} blew up (step {(T - t0) / steps:.3g} is too large for it); raise --steps")
    return 0


def _solver_from_args(args, system=None, z0=None):
    """The solver object of ``atlasnn solve``'s options (an option of another solver is refused);
    ``--solver auto``: the one ``solve`` would choose for the system."""
    from atlasnn.solver import default_solver, solver_from_name

    name = args.solver if args.solver != "auto" else default_solver(system, z0).name
    own = {"gauss": ("stages", "steps", "h"), "collocation": ("features", "seed"),
           "splitting": ("scheme", "h")}[name]
    options = {"stages": "stages", "step_mode": "steps", "h": "h", "features": "features", "seed": "seed",
               "rtol": "rtol", "atol": "atol", "scheme": "scheme"}
    given = {key: getattr(args, dest, None) for dest, key in options.items() if getattr(args, dest, None) is not None}
    for key in sorted(set(given) - set(own) - {"rtol", "atol"}):
        raise AtlasError(f"--{key} is not a setting of the {name} solver"
                         f"{' (the one --solver auto chose for this system)' if args.solver == 'auto' else ''}; "
                         f"drop it or choose the solver it belongs to with --solver")
    return solver_from_name(name, **given)


def _work_line(system, t0, T, sol) -> str:
    """What the march did, in one line."""
    info = sol.info
    if info.get("solver") == "splitting":
        return (f"{system.name}: [{t0:g}, {T:.6g}] by the splitting scheme {info['scheme']} (order {info['order']}, "
                f"{info['stages']} force evaluations a step) in {info['steps']} steps of h = {info['h']:.4g}, "
                f"{info['solve_time'] * 1e3:.1f} ms")
    work = (f"{info['rejected']} rejected, {info['iterations']} iterations" if "iterations" in info else
            f"{info['rejected']} rejected, {info['newton_iterations']} Gauss-Newton iterations")
    return (f"{system.name}: [{t0:g}, {T:.6g}] by {info.get('solver', 'the solver')} in {sol.n_windows} windows "
            f"({work}), {info['solve_time'] * 1e3:.1f} ms (first call, with compilation or cache load: "
            f"{info['first_call_time']:.2f} s)")


def cmd_solve(args) -> int:
    import numpy as np

    from atlasnn.evaluation import reference_solution
    from atlasnn.solver import solve

    from atlasnn.experiments.config import builtin_config_path, builtin_experiments

    args.steps = 1  # the problem's reading shares integrate's; its steps are not used here
    if args.config_pos in builtin_experiments() and not Path(args.config_pos).exists():
        args.config_pos = str(builtin_config_path(args.config_pos))  # a built-in experiment by name
    system, z0, t0, T, _ = _integrate_problem(args)
    solver = _solver_from_args(args, system, z0)
    if args.save is not None and Path(args.save).exists():
        raise AtlasError(f"--save {args.save}: the file exists; choose another path or remove it")
    if args.save is not None and not Path(args.save).resolve().parent.is_dir():
        raise AtlasError(f"--save {args.save}: the folder {Path(args.save).resolve().parent} does not exist; create it "
                         "first (checked before solving, so nothing is lost)")
    sol = solve(system, z0, (t0, T), solver=solver)
    info = sol.info
    print(_work_line(system, t0, T, sol))
    if info.get("advice"):
        print(f"note: {info['advice']}")
    if info.get("time_scale_chosen"):
        print(f"note: marched in a fictitious time (windows counted in it), time_scale={info['time_scale_chosen']}")
    est = sol.estimate(z0=z0)
    trust = "" if est.trusted else f" (quantitative only up to t = {est.trusted_until:.4g}: past it the error is large)"
    print(f"estimated max error: {est.max_abs:.3e} = {est.relative_max:.3e} of the state's range{trust}")
    if args.check:
        t = np.linspace(t0, T, 2000)
        ref = reference_solution(system, z0, t, **CHECK_TOLERANCES)  # DOP853 at its tightest
        # the reference's own error, as far as it can be told: how far the next looser run is from it
        blur = float(np.abs(reference_solution(system, z0, t, **CHECK_LOOSER) - ref).max())
        err, scale = float(np.abs(sol(t) - ref).max()), float(np.ptp(ref, axis=0).max())
        print(f"true max error against DOP853 at rtol {CHECK_TOLERANCES['rtol']:g} (2000 times): {err:.3e} = "
              f"{err / scale:.3e} of the range"
              + (f"; estimate / true = {est.max_abs / err:.2f}" if err > 3 * blur else
                 f": within what the reference resolves ({blur:.1e}, its distance from DOP853 at "
                 f"{CHECK_LOOSER['rtol']:g}), so the true error is not known better than that"))
    if args.save is not None:
        from atlasnn.checkpoint import save

        save(args.save, sol, extra={"interval": [t0, T]})
        print(f"wrote {args.save}")
    return 0
