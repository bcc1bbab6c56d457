"""What a first `atlasnn.solve` costs in a fresh process: with the compilation cache off (cold), with
an empty one (the first run ever: it also exports the program to disk) and with it warm, on
Hénon–Heiles [0, 24π] at the defaults; and cold only on the Pythagorean three-body problem
[0, 70], the outer solar system over 10⁶ days and the NLS on 512 points over [0, 1]; beside them
Diffrax's Dopri8 on the same two gravitational fields, its first (compiling) call. Each run is
its own Python process; it reports the import, the first solve (of which the first call of the
compiled program: compilation or cache load, tracing, and the march itself), the first evaluation
at 2 000 times and a second solve with its evaluation (the warm cost).

    python -m benchmarks.solver_first_run --out docs/benchmarks/solver_first_run.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy as np
from atlasnn import solve
from atlasnn.systems import henon_heiles, nls
t1 = time.perf_counter()
which = sys.argv[1]
if which == "henon-heiles":
    s, z0, T = henon_heiles(), [0.3, -0.3, 0.3, 0.15], 24 * np.pi
elif which == "pythagorean":
    from benchmarks.problems import pythagorean_system
    s, z0, T = pythagorean_system(), None, 70.0
elif which == "outer-solar":
    from benchmarks.outer_solar import outer_solar_system
    s, z0, T = outer_solar_system(), None, 1e6
else:
    s, z0, T = nls(points=512), None, 1.0
t = np.linspace(0.0, T, 2000)
sol = solve(s, z0, (0.0, T))
t2 = time.perf_counter()
sol(t)
t3 = time.perf_counter()
solve(s, z0, (0.0, T))(t)
t4 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "first_solve": t2 - t1, "first_program_call": sol.info["first_call_time"],
                  "first_evaluation": t3 - t2, "second_solve_and_evaluation": t4 - t3}))
"""


#: the anchor: Diffrax's Dopri8 on the same field (rtol 1e-10, 2 000 saved times), jitted, its
#: first call (compiling it and solving) and its second, in a fresh process
DIFFRAX_CHILD = r"""
import json, sys, time
import numpy as np, jax, diffrax
jax.config.update("jax_enable_x64", True)
which = sys.argv[1]
if which == "pythagorean":
    from benchmarks.problems import pythagorean_system
    s, T = pythagorean_system(), 70.0
else:
    from benchmarks.outer_solar import outer_solar_system
    s, T = outer_solar_system(), 1e6
term = diffrax.ODETerm(lambda t, y, args: s.vector_field(y[None])[0])
saveat = diffrax.SaveAt(ts=np.linspace(0.0, T, 2000))
control = diffrax.PIDController(rtol=1e-10, atol=1e-12)
run = jax.jit(lambda y0: diffrax.diffeqsolve(term, diffrax.Dopri8(), 0.0, T, None, y0, saveat=saveat,
                                             stepsize_controller=control, max_steps=1_000_000).ys)
z0 = np.asarray(s.z0, np.float64)
t0 = time.perf_counter()
run(z0).block_until_ready()
t1 = time.perf_counter()
run(z0).block_until_ready()
t2 = time.perf_counter()
print(json.dumps({"first_call": t1 - t0, "second_call": t2 - t1}))
"""


def run(cache: str, problem: str = "henon-heiles", child: str = CHILD) -> dict:
    """One fresh process with the cache in ``cache`` (a directory, or "off")."""
    env = dict(os.environ)
    env["ATLASNN_CACHE_DIR"] = cache
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(Path(__file__).resolve().parent.parent),
                                                      env.get("PYTHONPATH")]))
    out = subprocess.run([sys.executable, "-c", child, problem], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/benchmarks/solver_first_run.json")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as warm:
        run(warm)  # fills this cache (not recorded)
        rows = {"cold (cache off)": [run("off") for _ in range(2)],
                "first ever (empty cache: compiles, exports and stores)": [run(tempfile.mkdtemp()) for _ in range(2)],
                "warm cache": [run(warm) for _ in range(3)],
                **{f"cold (cache off), {name}": [run("off", name)] for name in ("pythagorean", "outer-solar", "nls")},
                **{f"Diffrax Dopri8, cold, {name}": [run("off", name, DIFFRAX_CHILD)]
                   for name in ("pythagorean", "outer-solar")}}
    for k, v in rows.items():
        for r in v:
            print(k, {a: round(b, 3) for a, b in r.items()})
    Path(args.out).write_text(json.dumps({"command": "python -m benchmarks.solver_first_run", "runs": rows},
                                         indent=1))


if __name__ == "__main__":
    main()
