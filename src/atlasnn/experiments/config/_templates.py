"""``atlasnn init``: a commented experiment template for the user's own system.

The template is a single-interval experiment or a transfer (source → target) one, for a built-in
system or a Hamiltonian given as an expression (default: the pendulum H = p²/2 − cos q). Its
settings are the paper's for the nonlinear oscillator (oscillator-short, oscillator-transfer);
every key carries its meaning from the schema as a comment, and a tiny [quick] table makes
``atlasnn run NAME.toml --quick`` a smoke test (a few hundred epochs). The text is validated
(with and without --quick) before it is written.
"""

from __future__ import annotations

import inspect
import re
import textwrap
from pathlib import Path
from typing import Any, Mapping, Sequence

from atlasnn.fileio import parse_toml
from atlasnn.nn import MODELS
from atlasnn.systems import BUILTIN_SYSTEMS, builtin_system
from atlasnn.errors import ConfigError
from atlasnn.experiments.config._config import QUICK, parse_config
from atlasnn.experiments.config._reference import toml_value
from atlasnn.experiments.config._schema import key_spec

PENDULUM = ("p**2/2 - cos(q)", ("q",), ("p",))



def _system_items(system: str | None, hamiltonian: str | None, coordinates: Sequence[str],
                  momenta: Sequence[str], z0: Sequence[float] | None, separable: bool,
                  given: Mapping[str, float]) -> list[tuple[str, Any]]:
    if system is not None:
        sysm = builtin_system(system)  # refuses an unknown name (one line)
        key = system.replace("-", "_")
        params = {n: p.default for n, p in inspect.signature(BUILTIN_SYSTEMS[key].factory).parameters.items()
                  if isinstance(p.default, (int, float)) and not isinstance(p.default, bool)}
        unknown = sorted(set(given) - set(params))
        if unknown:
            raise ConfigError(f"--params {unknown[0]}: not a parameter of {key} (its parameters: {sorted(params)})")
        params = {k: float(v) for k, v in {**params, **given}.items()}
        items = [("name", key)] + ([("params", params)] if params else [])
        return items + [("z0", [float(x) for x in (z0 if z0 is not None else sysm.z0)])]
    d = len(coordinates)
    items = [("hamiltonian", hamiltonian), ("coordinates", list(coordinates)), ("momenta", list(momenta)),
             ("separable", separable)] + ([("params", {k: float(v) for k, v in given.items()})] if given else [])
    return items + [("z0", [float(x) for x in z0] if z0 is not None else [1.0] * d + [0.0] * d)]


def _tables(name: str, transfer: bool, system_items: list, what: str, T: Any = "4*pi", march: bool = False,
            solve: bool = False) -> list[tuple[str, list[tuple[str, Any]]]]:
    """(table, [(key, value)]) in file order: the paper's oscillator settings; ``march``: the
    models time-marched over [0, T] instead of trained directly; ``solve``: the Gauss
    collocation's column too."""
    interval = "source [0, 4pi] -> target [0, 20pi]" if transfer else f"one interval [0, {T}]"
    interval += ", time-marched" if march else ""
    top = [("name", name), ("description", f"{what}: {interval}"), ("kind", "transfer" if transfer else "short"),
           ("models", [] if march else list(MODELS)), ("seeds", [0])]
    train = [("epochs", 40000 if transfer else 100000), ("lr", 5e-3 if transfer else 8e-3),
             ("betas", [0.999, 0.9999]), ("lam_reg", 1.0), ("n_points", 200), ("sigma_per_T", 0.03)]
    train += [("tolerance", 4e-5)] if transfer else []
    train += [("best_rule", "release"), ("chunk", 2000)]
    tables = [("", top), ("system", system_items), ("network", [("width", 80 if transfer else 50), ("depth", 2),
                                                                  ("activation", "sin")])]
    if transfer:
        tables += [("source", [("t0", 0.0), ("T", "4*pi")]), ("source.train", [("n_points", 200), ("lr", 8e-3)]),
                   ("target", [("t0", 0.0), ("T", "20*pi")]), ("target.train", [("n_points", 500)])]
    else:
        tables += [("interval", [("t0", 0.0), ("T", T)])]
    tables += [("train", train)]
    tables += [(f"gamma_init.{k.name}", [(g, 1.0) for g in k.gamma_names]) for k in MODELS.values() if k.gamma_names]
    if transfer:
        tables += [("transfer", [("thaw", False), ("carry_adam", True), ("baseline", True)])]
    if march:
        tables += [("march", [("models", ["atlas_exp"])])]
    if solve:
        tables += [("solve", [("method", "gauss"), ("rtol", 1e-11), ("atol", 1e-13)])]
    tables += [("evaluation", [("eval_points", 5000 if transfer else 2000), ("fine_factor", 100)])]
    return tables


def _comment(text: str) -> list[str]:
    return textwrap.wrap(text, 98, initial_indent="# ", subsequent_indent="# ", break_on_hyphens=False)


def _render(path_name: str, tables, transfer: bool) -> str:
    run = f"atlasnn run {path_name}"
    what = ("A transfer run: every model is trained on the short source interval, then continued on the "
            "long target interval with its time scaling's γ frozen." if transfer else
            "A single-interval run: every model is trained on [t0, T] and compared with symplectic Euler (SE) "
            "and a reference solution.")
    lines = _comment(f"{path_name}: an atlasnn experiment, written by `atlasnn init`; edit it for your system. "
                     f"{what} The settings are the paper's for the nonlinear oscillator. Every key is explained "
                     "above it; keys left out take their defaults (all of them: `atlasnn config`, or docs/CONFIG.md).")
    lines += [
        "#",
        f"#   {run} --quick    a smoke test, a few hundred epochs (the [quick] table at the end)",
        f"#   {run}            the full budget",
    ]
    for table, items in tables:
        lines.append("")
        if table:
            lines += _comment(key_spec(table).meaning) + [f"[{table}]"]
        for key, value in items:
            lines += _comment(key_spec(f"{table}.{key}" if table else key).meaning)
            lines.append(f"{key} = {toml_value(value)}")
    lines += [""] + _comment(
        "A smoke test, not a result: a few hundred epochs check that this file runs end to end "
        f"(`{run} --quick`); the errors it reports are far from converged. --quick merges these "
        "keys over the ones above.") + ["[quick]"]
    for dotted, value in QUICK:
        lines.append(f"{dotted} = {toml_value(value)}  # instead of {dotted} above")
    return "\n".join(lines) + "\n"


def _check(text: str, source: str) -> None:
    data = parse_toml(text, source)
    parse_config(data, source=source)
    parse_config(data, quick=True, source=source)


def init_template(path: str | Path, *, transfer: bool = False, system: str | None = None,
                  hamiltonian: str | None = None, coordinates: Sequence[str] = (),
                  momenta: Sequence[str] = (), z0: Sequence[float] | None = None,
                  params: Mapping[str, float] | None = None, T: Any = "4*pi", march: bool = False,
                  solve: bool = False) -> str:
    """The text of a validated template for ``path`` (not written). Default system: the pendulum.
    ``params``: values of named parameters (a built-in's, which must exist, or names used in H).
    ``T``: the interval's end (a number or an expression such as "20*pi"); ``march``: time-march
    the model instead of training it directly (for anything longer than a few periods);
    ``solve``: add the Gauss collocation's column. Neither goes with ``transfer``."""
    path = Path(path)
    if transfer and (march or solve or T != "4*pi"):
        raise ConfigError("--march, --solve and --T make a single-interval template; a transfer one has source and "
                          "target intervals (edit them in the file)")
    if system is not None and hamiltonian is not None:
        raise ConfigError("give --system or --hamiltonian, not both")
    if hamiltonian is None and (coordinates or momenta):
        raise ConfigError("--coordinates and --momenta go with --hamiltonian")
    if hamiltonian is not None and not (coordinates and momenta):
        raise ConfigError("--hamiltonian needs --coordinates and --momenta (e.g. --coordinates q --momenta p)")
    if system is None and hamiltonian is None:
        hamiltonian, coordinates, momenta = PENDULUM
        z0 = [1.0, 0.0] if z0 is None else z0
        what = f"the pendulum H = {hamiltonian}"
    else:
        what = f"the {system} system" if system is not None else f"H = {hamiltonian}"
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", path.stem).strip("-") or "experiment"
    text = None
    for separable in (True, False):  # separable = true if H passes the check
        items = _system_items(system, hamiltonian, coordinates, momenta, z0, separable, dict(params or {}))
        text = _render(path.name, _tables(name, transfer, items, what, T, march, solve), transfer)
        try:
            _check(text, str(path))
            return text
        except ConfigError as exc:
            if not (separable and system is None and str(exc).startswith("system.separable")):
                raise
    raise AssertionError("unreachable")  # the separable = false pass returns or raises


def write_template(path: str | Path, *, force: bool = False, **options) -> str:
    """Write :func:`init_template`'s text to ``path``; an existing file only with ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise ConfigError(f"{path} exists; pass --force to overwrite it")
    text = init_template(path, **options)
    try:
        with path.open("w" if force else "x", encoding="utf-8") as f:
            f.write(text)
    except FileExistsError:
        raise ConfigError(f"{path} exists; pass --force to overwrite it") from None
    except OSError as exc:
        raise ConfigError(f"cannot write {path}: {exc.strerror or exc}") from None
    return text
