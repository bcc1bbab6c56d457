"""Rerun drift: what a rerun of the same seed reproduces under another XLA setting or CPU.

Two small cases of oscillator-short with one model column (``--model``, default hnn, the column
that differed in the report that prompted this), each trained with ``atlasnn run --jobs 1
--seed-batch 1`` in a fresh process per *environment*, with the persistent compilation cache off
(every run compiles afresh, as on another machine):

- ``small``: the config's own size (K = 200 collocation points, 50x2), 20 000 epochs, seeds 0 and 1,
  every environment below;
- ``large``: K = 500, 80x2 (the size of oscillator-transfer's target and oscillator-long), 5 000
  epochs, seed 0, the thread-count environments.

The environments (each is compared with ``default`` unless said otherwise):

- ``default``        no XLA_FLAGS: the in-process setting of ``--jobs 1``;
- ``control``        the same again (a same-machine rerun: must be bit-identical);
- ``workers``        ``WORKER_XLA_FLAGS`` of atlasnn's worker processes (``--jobs J > 1``);
- ``isa-avx2``       ``--xla_cpu_max_isa=AVX2``: XLA's LLVM code generator stops at AVX2, as on a
                     CPU without AVX-512;
- ``isa-avx``        ``--xla_cpu_max_isa=AVX`` (no AVX2, no FMA in the generated code);
- ``no-ynn``         ``--xla_cpu_experimental_ynn_fusion_type=``: the dots and reductions that XLA
                     otherwise hands to YNNPACK (kernels picked at run time by the CPU's ISA, which
                     ``xla_cpu_max_isa`` does not cap) stay in XLA's own kernels: another kernel for
                     the same float32 sums;
- ``one-core``       no XLA_FLAGS, the process pinned to one core (a machine with fewer cores);
- ``one-core-no-ynn``  ``no-ynn``'s flag, pinned to one core; compared with ``no-ynn``;
- ``seed-batch``     no XLA_FLAGS, ``--seed-batch 2`` (the seeds trained as one batched program,
                     which ``auto`` picks or not depending on the machine's core count);
- ``ulp-z0``         no XLA_FLAGS, the initial state's first component moved by one float32 ulp
                     (a deliberate 1-ulp perturbation of the input).

For each environment against its reference: are the trained parameters and the loss histories
(``models/*.npz``: ``param_*``, ``history_loss``) bit-identical; the first epoch whose loss differs
(``history_loss[e]`` is the loss of the parameters after e updates); the relative difference of the
loss at a few epochs (the amplification); and the final error metrics from ``results.json``.
Two checks without training: a small MLP-like program compiled under each ISA flag with
``--xla_dump_to`` (zmm/ymm registers and FMA in the generated code, and how many operations go to
YNNPACK), and which of ``WORKER_XLA_FLAGS`` XLA applies (its parser stops at the first word that
does not start with ``--``).

Usage::

    python benchmarks/rerun_drift.py [--cases small large] [--model hnn] [--epochs N] [--seeds N]
        [--envs default control workers isa-avx2 ...] [--out docs/benchmarks/rerun_drift.json]

About 6 minutes on a 2-core CPU.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script: `python benchmarks/rerun_drift.py`
    sys.path.insert(0, str(ROOT))

from benchmarks.common import machine_info

BASE_CONFIG = ROOT / "src" / "atlasnn" / "experiments" / "configs" / "oscillator-short.toml"
LOSS_EPOCHS = (0, 1, 10, 100, 1000, 10000)  # plus the last


def _worker_flags() -> str:
    try:
        from atlasnn.experiments._local import WORKER_XLA_FLAGS
        return WORKER_XLA_FLAGS
    except ImportError:  # pragma: no cover
        return "--xla_cpu_multi_thread_eigen=false"


def environments() -> dict[str, dict]:
    """name -> {xla_flags, one_core, seed_batch, ulp_z0, describes}."""
    base = {"xla_flags": None, "one_core": False, "seed_batch": 1, "ulp_z0": False, "ref": "default"}
    no_ynn = "--xla_cpu_experimental_ynn_fusion_type="
    envs = {
        "default": ({}, "no XLA_FLAGS, --jobs 1 (in-process)"),
        "control": ({}, "the same as default, rerun (same machine)"),
        "workers": ({"xla_flags": _worker_flags()}, "atlasnn's worker-process flags (--jobs J > 1)"),
        "isa-avx2": ({"xla_flags": "--xla_cpu_max_isa=AVX2"}, "LLVM codegen capped at AVX2 (a CPU without AVX-512)"),
        "isa-avx": ({"xla_flags": "--xla_cpu_max_isa=AVX"}, "LLVM codegen capped at AVX (no AVX2/FMA)"),
        "no-ynn": ({"xla_flags": no_ynn}, "no YNNPACK fusions: dots/reductions in XLA's own kernels"),
        "one-core": ({"one_core": True}, "no XLA_FLAGS, pinned to one core"),
        "one-core-no-ynn": ({"xla_flags": no_ynn, "one_core": True, "ref": "no-ynn"},
                            "no YNNPACK fusions, pinned to one core (against no-ynn)"),
        "seed-batch": ({"seed_batch": 2}, "no XLA_FLAGS, --seed-batch 2 (seeds in one program)"),
        "ulp-z0": ({"ulp_z0": True}, "no XLA_FLAGS, z0[0] moved up by one float32 ulp"),
    }
    return {k: {**base, **v, "describes": d} for k, (v, d) in envs.items()}


# ---------------------------------------------------------------------------- the config
def _write_config(path: Path, model: str, epochs: int, seeds: int, ulp_z0: bool,
                  width: int | None = None, points: int | None = None) -> dict:
    """A copy of oscillator-short: one model column, ``epochs`` epochs, seeds 0..seeds-1 (and, if
    given, another network width and number of collocation points)."""
    import numpy as np

    text = BASE_CONFIG.read_text(encoding="utf-8")
    text = re.sub(r'^name = ".*"$', 'name = "rerun-drift"', text, count=1, flags=re.MULTILINE)
    text = re.sub(r"^models = \[.*\]$", f'models = ["{model}"]', text, count=1, flags=re.MULTILINE)
    text = re.sub(r"^seeds = \[.*\]$", f"seeds = {list(range(seeds))}", text, count=1, flags=re.MULTILINE)
    text = re.sub(r"^epochs = \d+$", f"epochs = {epochs}", text, count=1, flags=re.MULTILINE)
    text = re.sub(r"^chunk = \d+$", f"chunk = {min(2000, epochs)}", text, count=1, flags=re.MULTILINE)
    text = text.split("\n[quick]")[0]  # the quick variant is not used
    if width is not None:
        text = re.sub(r"^width = \d+$", f"width = {width}", text, count=1, flags=re.MULTILINE)
    if points is not None:
        text = re.sub(r"^n_points = \d+$", f"n_points = {points}", text, count=1, flags=re.MULTILINE)
        text = re.sub(r"^eval_points = \d+$", f"eval_points = {10 * points}", text, count=1, flags=re.MULTILINE)
    z0 = [1.3, 1.0]
    m = re.search(r"^z0 = \[([^\]]*)\]$", text, flags=re.MULTILINE)
    if m:
        z0 = [float(v) for v in m.group(1).split(",")]
    if ulp_z0:
        f32 = np.float32(z0[0])
        z0[0] = float(np.nextafter(f32, np.float32(np.inf)))  # exactly representable in float32
        text = text.replace(m.group(0), f"z0 = [{', '.join(repr(v) for v in z0)}]")
    path.write_text(text, encoding="utf-8")
    return {"model": model, "epochs": epochs, "seeds": list(range(seeds)), "z0": z0,
            "width": int(re.search(r"^width = (\d+)$", text, re.MULTILINE).group(1)),
            "n_points": int(re.search(r"^n_points = (\d+)$", text, re.MULTILINE).group(1))}


# ---------------------------------------------------------------------------- one run
def _run(name: str, env: dict, spec: dict, model: str, timeout: float, work: Path) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    cfg_path = work / f"{name}.toml"
    cfg = _write_config(cfg_path, model, spec["epochs"], spec["seeds"], env["ulp_z0"], spec["width"], spec["points"])
    out = work / name
    cmd = [str(Path(sys.executable).with_name("atlasnn")), "run", str(cfg_path), "--out", str(out),
           "--overwrite", "--jobs", "1", "--seed-batch", str(env["seed_batch"]), "--no-progress"]
    child_env = dict(os.environ)
    child_env.pop("XLA_FLAGS", None)
    if env["xla_flags"] is not None:
        child_env["XLA_FLAGS"] = env["xla_flags"]
    child_env["ATLASNN_CACHE_DIR"] = "off"  # compile afresh, as on another machine
    child_env["TF_CPP_MIN_LOG_LEVEL"] = "1"  # keep XLA's warnings (an unknown ISA name, ...)
    pre = None
    if env["one_core"]:
        core = min(os.sched_getaffinity(0))
        pre = lambda: os.sched_setaffinity(0, {core})
    t = time.perf_counter()
    proc = subprocess.run(cmd, env=child_env, capture_output=True, text=True, preexec_fn=pre, timeout=timeout,
                          check=False)
    wall = time.perf_counter() - t
    warnings = sorted({ln.strip() for ln in proc.stderr.splitlines()
                       if re.match(r"^[WEF]\d{4} ", ln.strip()) or "Unknown" in ln or "nknown flag" in ln})
    rec = {"env": name, "describes": env["describes"], "xla_flags": env["xla_flags"],
           "one_core": env["one_core"], "seed_batch": env["seed_batch"], "config": cfg,
           "command": " ".join(cmd), "rc": proc.returncode, "wall_s": round(wall, 1),
           "xla_warnings": warnings[:10]}
    if proc.returncode != 0:
        rec["error"] = (proc.stderr or proc.stdout)[-2000:]
        return rec
    rec["dir"] = str(out)
    return rec


def _load(out: Path, model: str, seed: int) -> dict:
    import numpy as np

    z = np.load(out / "models" / f"{model}_seed{seed}.npz", allow_pickle=False)
    params = {k: z[k] for k in z.files if k.startswith("param_")}
    res = json.loads((out / "results.json").read_text())
    run = next(r for r in res["runs"] if r["model"] == model and r["seed"] == seed and r["role"] == "short")
    m = run["metrics"]
    task = json.loads((out / "tasks" / f"short_{model}_seed{seed}.json").read_text())["records"][0]
    metrics = {**{f"l2_{k}": v for k, v in m["l2_discrete"].items()},
               **{f"maxabs_{k}": v for k, v in m["max_abs"].items()},
               "relative_max": m.get("relative_max"), "energy_drift": m.get("energy_drift")}
    return {"params": params, "loss": np.asarray(z["history_loss"]), "metrics": metrics,
            "best_epoch": task.get("best_epoch"), "returned_loss": task.get("returned_loss"),
            "final_loss": task.get("final_loss")}


def _rel(a: float, b: float) -> float:
    return abs(a - b) / abs(a) if a != 0 else float(abs(a - b))


def compare(ref: dict, other: dict, epochs: tuple[int, ...]) -> dict:
    import numpy as np

    la, lb = ref["loss"], other["loss"]
    n = min(len(la), len(lb))
    diff = np.nonzero(la[:n] != lb[:n])[0]
    same_params = all(np.array_equal(ref["params"][k], other["params"][k]) for k in ref["params"])
    pmax = max(float(np.max(np.abs(ref["params"][k] - other["params"][k])) /
                     max(float(np.max(np.abs(ref["params"][k]))), 1e-30)) for k in ref["params"])
    at = {str(e): _rel(float(la[e]), float(lb[e])) for e in (*epochs, n - 1) if e < n}
    metrics = {k: {"ref": v, "this": other["metrics"].get(k),
                   "rel_diff": _rel(v, other["metrics"][k]) if other["metrics"].get(k) is not None and v is not None
                   else None}
               for k, v in ref["metrics"].items()}
    return {"params_identical": bool(same_params), "loss_identical": bool(len(diff) == 0 and len(la) == len(lb)),
            "first_loss_diff_epoch": int(diff[0]) if len(diff) else None,
            "epochs_with_loss_diff": len(diff), "epochs_compared": int(n),
            "loss_rel_diff_at": at, "params_max_rel_diff": pmax,
            "best_epoch": [ref["best_epoch"], other["best_epoch"]], "metrics": metrics}


# ---------------------------------------------------------------------------- ISA check
ISA_CHILD = r"""
import jax, jax.numpy as jnp
k1, k2 = jax.random.split(jax.random.PRNGKey(0))
W = jax.random.normal(k1, (50, 50), jnp.float32) / 7
t = jnp.linspace(0, 12.5, 200, dtype=jnp.float32)[:, None]
def f(W, t):
    h = jnp.sin(t * W[0] + W[1])
    h = jnp.sin(h @ W + W[2])
    return jnp.mean((h @ W[:, :2]) ** 2) + jnp.exp(-h).sum()
print(float(jax.jit(jax.value_and_grad(f))(W, t)[0]).hex())
"""


def isa_check(flags: list[str | None]) -> list[dict]:
    """Compile a small MLP loss+gradient under each flag; count what the generated code uses."""
    objdump = shutil.which("objdump")
    out = []
    for fl in flags:
        with tempfile.TemporaryDirectory() as d:
            env = dict(os.environ)
            env["XLA_FLAGS"] = f"{fl or ''} --xla_dump_to={d}".strip()
            env["TF_CPP_MIN_LOG_LEVEL"] = "1"
            p = subprocess.run([sys.executable, "-c", ISA_CHILD], env=env, capture_output=True, text=True, timeout=120,
                               check=False)
            rec = {"xla_flags": fl, "rc": p.returncode, "value_hex": p.stdout.strip() or None,
                   "warnings": sorted({ln.strip() for ln in p.stderr.splitlines() if "nknown" in ln})[:5]}
            files = [f for f in os.listdir(d) if "jit_f" in f]
            hlo = "".join(Path(d, f).read_text(errors="replace") for f in files
                          if f.endswith("cpu_after_optimizations.txt"))
            rec["ynn_fusions"] = hlo.count("__ynn_fusion\"")
            rec["plain_dots"] = len(re.findall(r" dot\(", hlo))
            if objdump:
                asm = "".join(subprocess.run([objdump, "-d", str(Path(d, f))], capture_output=True, text=True,
                                             check=False).stdout
                              for f in files if f.endswith(".o"))
                rec.update(zmm=asm.count("zmm"), ymm=asm.count("ymm"), fma=len(re.findall(r"vfn?madd", asm)))
            out.append(rec)
    return out


# ---------------------------------------------------------------------------- machine
def cpu_record() -> dict:
    info: dict = {}
    try:
        text = Path("/proc/cpuinfo").read_text()
        name = re.search(r"^model name\s*:\s*(.*)$", text, re.MULTILINE)
        flags = re.search(r"^flags\s*:\s*(.*)$", text, re.MULTILINE)
        info["model_name"] = name.group(1).strip() if name else None
        fl = flags.group(1).split() if flags else []
        info["simd_flags"] = [f for f in ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512dq", "avx512bw",
                                          "avx512vl", "avx512_vnni", "avx512_bf16", "amx_tile") if f in fl]
    except OSError:
        pass
    return info


# ---------------------------------------------------------------------------- output
def _fmt(x) -> str:
    if x is None:
        return "–"
    return "0" if x == 0 else f"{x:.1e}"


def table(rows: list[dict], seeds: list[int], key_metrics: list[str]) -> str:
    head = ("| env | vs | seed | params = | loss = | 1st diff epoch | Δloss rel @10 | @100 | @1000 | @last | "
            + " | ".join(key_metrics) + " | Δ" + " rel | Δ".join(key_metrics) + " rel |")
    lines = [head, "|" + "---|" * (10 + 2 * len(key_metrics))]
    for r in rows:
        if "compare" not in r:
            lines.append(f"| {r['env']} | {r['vs']} | – | failed (rc {r['rc']}) |" + " |" * (7 + 2 * len(key_metrics)))
            continue
        for s in seeds:
            c = r["compare"][str(s)]
            at = c["loss_rel_diff_at"]
            last = at[max(at, key=int)]
            vals = [c["metrics"][k]["this"] for k in key_metrics]
            rels = [c["metrics"][k]["rel_diff"] for k in key_metrics]
            lines.append(
                f"| {r['env']} | {r['vs']} | {s} | {'yes' if c['params_identical'] else 'no'} | "
                f"{'yes' if c['loss_identical'] else 'no'} | {c['first_loss_diff_epoch'] if c['first_loss_diff_epoch'] is not None else '–'} | "
                f"{_fmt(at.get('10'))} | {_fmt(at.get('100'))} | {_fmt(at.get('1000'))} | {_fmt(last)} | "
                + " | ".join(f"{v:.4g}" for v in vals) + " | " + " | ".join(_fmt(x) for x in rels) + " |")
    return "\n".join(lines)


CASES = {
    # the default config's size: every environment
    "small": {"width": None, "points": None, "epochs": 20000, "seeds": 2, "envs": None},
    # the size of oscillator-transfer's target / oscillator-long (K = 500, 80x2): the thread-count cases
    "large": {"width": 80, "points": 500, "epochs": 5000, "seeds": 1,
              "envs": ["default", "control", "workers", "one-core", "no-ynn", "one-core-no-ynn"]},
}


def run_case(case: str, spec: dict, args, all_envs: dict, work: Path) -> dict:
    names = ["default"] + [e for e in (spec["envs"] or args.envs) if e != "default"]
    if spec["seeds"] < 2 and "seed-batch" in names:
        names.remove("seed-batch")
    for n in list(names):  # an environment's reference runs first
        ref = all_envs[n]["ref"]
        if ref not in names:
            names.insert(names.index(n), ref)
    seeds = list(range(spec["seeds"]))
    rows, loaded = [], {}
    for name in names:
        rec = _run(name, all_envs[name], spec, args.model, args.timeout, work / case)
        print(f"  [{case}] {name}: rc {rec['rc']}, {rec['wall_s']} s"
              + (f"; XLA: {rec['xla_warnings'][0]}" if rec["xla_warnings"] else ""), flush=True)
        if "error" not in rec:
            loaded[name] = {s: _load(work / case / name, args.model, s) for s in seeds}
        rows.append(rec)
    for rec in rows:
        ref = all_envs[rec["env"]]["ref"]
        rec["vs"] = ref
        if rec["env"] in loaded and ref in loaded:
            got = loaded[rec["env"]]
            rec["seeds"] = {str(s): {k: got[s][k] for k in ("metrics", "best_epoch", "returned_loss", "final_loss")}
                            for s in seeds}
            rec["compare"] = {str(s): compare(loaded[ref][s], got[s], LOSS_EPOCHS) for s in seeds}
    cfg = next((r["config"] for r in rows if "config" in r), {})
    text = table(rows, seeds, ["l2_x", "l2_p", "relative_max"])
    head = (f"[{case}] oscillator-short, {args.model} {cfg.get('width')}x2, K = {cfg.get('n_points')}, "
            f"{spec['epochs']} epochs, seeds {seeds}")
    return {"case": case, "title": head, "config": cfg, "environments": {n: all_envs[n] for n in names},
            "runs": rows, "table": text}


def flag_parse_check() -> dict:
    """Does XLA apply WORKER_XLA_FLAGS, and the flags written after them?"""
    flags = _worker_flags()
    out = {"worker_xla_flags": flags}
    code = "import jax.numpy as j; j.ones(3).sum().block_until_ready()"
    for label, xla in (("dump_after_worker_flags", f"{flags} --xla_dump_to={{d}}"),
                       ("dump_before_worker_flags", f"--xla_dump_to={{d}} {flags}")):
        with tempfile.TemporaryDirectory() as d:
            env = dict(os.environ, XLA_FLAGS=xla.format(d=d))
            p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120,
                               check=False)
            opts = "".join(Path(d, f).read_text() for f in os.listdir(d) if f.endswith(".debug_options"))
            out[label] = {"xla_flags": xla.format(d="DIR"), "rc": p.returncode, "dump_written": bool(os.listdir(d)),
                          "debug_options": sorted({ln.strip() for ln in opts.splitlines() if ln.strip()}) or None}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    all_envs = environments()
    ap.add_argument("--model", default="hnn", choices=["hnn", "atlas_tanh", "atlas_exp"])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES),
                    help="small: K = 200, 50x2, 20 000 epochs, 2 seeds, every environment; "
                         "large: K = 500, 80x2, 5 000 epochs, 1 seed, the thread-count environments")
    ap.add_argument("--epochs", type=int, default=None, help="override every case's epochs")
    ap.add_argument("--seeds", type=int, default=None, help="override every case's seeds (0..N-1)")
    ap.add_argument("--envs", nargs="+", default=list(all_envs), choices=list(all_envs),
                    help="environments of the small case (default is always run, first)")
    ap.add_argument("--no-isa-check", dest="isa_check", action="store_false")
    ap.add_argument("--timeout", type=float, default=300, help="seconds per training run")
    ap.add_argument("--keep", default=None, help="keep the run directories here (default: a temporary folder)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks" / "rerun_drift.json"))
    args = ap.parse_args(argv)
    if (args.epochs is not None and args.epochs < 10) or (args.seeds is not None and args.seeds < 1):
        ap.error("--epochs must be >= 10 and --seeds >= 1")

    t0 = time.perf_counter()
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="rerun_drift_"))
    work.mkdir(parents=True, exist_ok=True)
    cases = []
    try:
        for case in args.cases:
            spec = dict(CASES[case])
            spec["epochs"] = args.epochs or spec["epochs"]
            spec["seeds"] = args.seeds or spec["seeds"]
            cases.append(run_case(case, spec, args, all_envs, work))
        isa = isa_check([None, "--xla_cpu_max_isa=AVX2", "--xla_cpu_max_isa=AVX",
                         "--xla_cpu_experimental_ynn_fusion_type="]) if args.isa_check else None
        parse = flag_parse_check()
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)

    print("\nrerun drift: each env against its reference (vs); l2_* = results.json l2_discrete, "
          "relative_max = max error / state range; Δloss rel @e = |Δ history_loss[e]| / history_loss[e]")
    for c in cases:
        print(f"\n{c['title']}\n{c['table']}")
    if isa:
        print("\nISA check (a small MLP loss+grad): zmm/ymm/FMA instructions in XLA's generated code, "
              "YNNPACK fusions, same value as no flags")
        for r in isa:
            print(f"  {r['xla_flags'] or '(none)':45s} rc {r['rc']} zmm {r.get('zmm', '?')} ymm {r.get('ymm', '?')} "
                  f"fma {r.get('fma', '?')} ynn {r['ynn_fusions']} dots {r['plain_dots']} "
                  f"same value {r['value_hex'] == isa[0]['value_hex']}" + (f" {r['warnings']}" if r["warnings"] else ""))
    print("\nworker flags parse check: " + "; ".join(
        f"{k}: rc {v['rc']}, applied {v['debug_options']}" for k, v in parse.items() if isinstance(v, dict)))
    import jax
    import jaxlib

    info = machine_info()
    info["cpu"] = cpu_record()
    result = {
        "command": " ".join([Path(sys.executable).name, "benchmarks/rerun_drift.py",
                             *(argv if argv is not None else sys.argv[1:])]),
        "describes": __doc__.split("\n\n")[0],
        "model": args.model,
        "runner": "atlasnn run --jobs 1 --seed-batch 1 (the seed-batch env: 2), ATLASNN_CACHE_DIR=off, a fresh process each",
        "loss_history": "models/<model>_seed<s>.npz history_loss[e]: the loss of the parameters after e Adam updates",
        "versions": {"jax": jax.__version__, "jaxlib": jaxlib.__version__, **info.pop("versions")},
        "machine": info,
        "cases": cases,
        "isa_check": isa,
        "worker_flags_check": parse,
        "total_wall_s": round(time.perf_counter() - t0, 1),
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1, default=str))
    print(f"\ntotal {result['total_wall_s']} s; wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
