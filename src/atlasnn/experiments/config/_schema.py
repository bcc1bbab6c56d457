"""The experiment-config schema: every key of an experiment TOML file, declared once.

A key is one :class:`Key` in its table's :class:`TableSpec` in ``SCHEMA``: its name, its value
type (an instance of one of the types below; it carries the limits and the choices, checks a
value and describes itself), its default and a one-sentence meaning in the paper's words. From
these declarations come

- validation: :func:`parse_table` walks a table and its sub-tables, refusing an unknown key, a
  wrong type or an out-of-range value with one line naming the key and the value
  (:mod:`atlasnn.experiments.config._config` adds the few rules that relate several keys);
- the settings dataclasses ``TrainSettings``, ``EvaluationConfig`` and ``SystemConfig``, whose
  fields are the keys of [train], [evaluation] and [system] (:func:`settings_fields`);
- the config reference, ``atlasnn config`` and docs/CONFIG.md (:mod:`.config_reference`);
- the comments of the template ``atlasnn init`` writes (:mod:`.templates`).

How to add a key
----------------
1. Add one ``Key(...)`` to its table below: name, type with limits, default, meaning. That is all
   it takes for the key to be validated and documented; a key of [train], [evaluation] or
   [system] also becomes a field of TrainSettings / EvaluationConfig / SystemConfig, and a [train]
   key that is also a field of :class:`atlasnn.training._records.TrainConfig` reaches the trainer. A key of
   the top level, [network] or [transfer] also needs its field in ExperimentConfig (config.py
   fills the fields by name). A new table: a new ``TableSpec`` here and a ``Key(name,
   Sub("its id"), ...)`` where it sits.
2. If its value must agree with other keys (like T > t0), add a small named rule to config.py.
3. Regenerate the reference: ``atlasnn config --markdown > docs/CONFIG.md`` (a test compares it
   with the command's output, another checks that every key the parser accepts is documented).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from atlasnn.experiments.config._types import (
    LengthOrAuto,
    Bool,
    Choice,
    CountOrAuto,
    Integer,
    Key,
    NameList,
    Number,
    NumberList,
    NumberTable,
    Profiles,
    SeedList,
    String,
    Sub,
    TableSpec,
    TextTable,
    Variant,
    _fail,
    _key,
    _table,
)
from atlasnn.experiments.config._family_schema import FAMILY_TABLES
from atlasnn.evaluation import INTEGRATORS
from atlasnn.nn import ACTIVATIONS, MODELS, model_aliases
from atlasnn.systems import BUILTIN_SYSTEMS
from atlasnn.training import BEST_RULES, LR_SCHEDULES

# Upper limits: far beyond any sensible experiment, low enough that a typo (an extra digit, a
# float such as 1e20 where an integer belongs) fails here, as one line, and not as an overflow or
# an out-of-memory error halfway through a run.
MAX_EPOCHS = 1_000_000_000  # the trainer counts epochs in int32
MAX_POINTS = 1_000_000  # collocation points K, evaluation points
MAX_WIDTH = 10_000
MAX_DEPTH = 100
MAX_SEED = 2**32 - 1  # jax.random.PRNGKey takes a uint32 seed (larger ones wrap around silently)
MAX_SEEDS = 10_000
MAX_TIME = 1e6  # |t0|, |T|
MAX_STEPS = 100_000_000  # classical integrator steps (se_steps × fine_factor)
#: the schemes a config can run (atlasnn.experiments._schemes.SCHEMES, whose keys a test compares)
SCHEME_NAMES = ("baseline", "short", "transfer", "march", "solve")



def _model_names() -> tuple[str, ...]:
    return tuple(sorted(MODELS))


def _model_spellings() -> dict[str, str]:
    """Other names accepted for a model in configs (its scaling's name, its aliases)."""
    return {a: n for a, n in model_aliases().items() if a != n}


_MODEL_LIST = NameList(lambda: f"expected a non-empty list drawn from {sorted(MODELS)}", _model_names,
                       _model_spellings, unique=True)
_MODELS_OR_NONE = NameList(lambda: f"expected a list drawn from {sorted(MODELS)}", _model_names,
                           _model_spellings, nonempty=False, unique=True)



def parse_table(table: str, path: str, given: Any, *, sparse: bool = False) -> dict[str, Any]:
    """Validate the table ``given`` at ``path`` against ``SCHEMA[table]``: no unknown keys (an
    alias counts as its key; giving both is refused), every required key present, each value
    checked by its type; absent keys take their defaults unless ``sparse``."""
    spec = SCHEMA[table]
    names = [k.name for k in spec.keys]
    d = _table(path, given, set(names) | set(spec.aliases), set(names))  # aliases: accepted, not listed
    for alias, name in spec.aliases.items():
        if alias in d and name in d:
            _fail(_key(path, alias), d[alias], f"the same as {_key(path, name)}; give one of them")
    for k in spec.keys:
        if k.missing is not None and k.name not in d:
            k.fill(_key(path, k.name))
    spelled = {spec.aliases.get(k, k): k for k in d}  # key name -> the spelling given
    out: dict[str, Any] = {}
    for k in spec.keys:
        if k.name in spelled:
            out[k.name] = parse_value(k.type, _key(path, spelled[k.name]), d[spelled[k.name]])
        elif not (sparse or spec.sparse):
            if isinstance(k.type, Sub) and k.default is not None and k.missing is None:
                out[k.name] = parse_table(k.type.table, _key(path, k.name), {}, sparse=k.type.sparse)
            else:
                out[k.name] = k.fill(_key(path, k.name))
    return out


def top_level_keys() -> set[str]:
    """The keys a variant ([quick], a profile) may set: the top level's, but not ``quick``."""
    return {k.name for k in SCHEMA[""].keys} - {"quick"}


def parse_value(typ: Any, path: str, value: Any) -> Any:
    """Check and convert one value of type ``typ`` at ``path``: sub-tables and variants by the
    schema, every other type by itself."""
    if isinstance(typ, Sub):
        return parse_table(typ.table, path, value, sparse=typ.sparse)
    if isinstance(typ, (Variant, Profiles)):
        return typ.check(path, value, top_level_keys())
    return typ.parse(path, value)


def settings_fields(table: str) -> list[tuple[str, Any, Any]]:
    """``(name, type, field)`` of each key of a table, for :func:`dataclasses.make_dataclass`."""
    out = []
    for k in SCHEMA[table].keys:
        default = k.default
        if isinstance(default, list):  # lists are parsed to tuples
            default = tuple(default)
        f = dataclasses.field(default_factory=dict) if isinstance(default, dict) else dataclasses.field(default=default)
        out.append((k.name, Any, f))
    return out


def _builtin_systems() -> str:
    return "built-ins: " + ", ".join(sorted(BUILTIN_SYSTEMS))


def _integrators() -> tuple[str, ...]:
    return tuple(sorted(INTEGRATORS))


def _network_keys(width: int, scale: float, why: str) -> tuple[Key, ...]:
    """The keys of a network table ([network], [march.network]): their defaults differ."""
    return (
        Key("width", Integer(1, MAX_WIDTH), width, "Neurons per hidden layer."),
        Key("depth", Integer(1, MAX_DEPTH), 2, "Number of hidden layers."),
        Key("activation", Choice(lambda: tuple(sorted(ACTIVATIONS))), "sin", "Activation of the hidden layers."),
        Key("first_layer_scale", Number(low=0, low_open=True, high=1e3), scale,
            f"The first layer's initial weights are multiplied by this ({why})."),
    )


_STAGE_TIME = Number(low=-MAX_TIME, high=MAX_TIME, pi=True)
_GAMMA = Number(low=0, low_open=True)

# Every table, by id. A table's id is its path, except that [interval], [source] and [target]
# share "stage" and their train tables share "train".
_STATIC_TABLES: dict[str, TableSpec] = {
    "": TableSpec("The top level of an experiment file.", (
        Key("name", String(r"[A-Za-z0-9_.-]+", "use letters, digits, '-', '_' and '.' only",
                           "letters, digits, '-', '_', '.'"), None,
            "The experiment's name, used in the run directory's name and in its results.",
            default_text="the file's name without .toml"),
        Key("description", String(), "", "One line saying what the experiment is, shown by `atlasnn experiments` "
            "and in the results."),
        Key("suite", String(r"[A-Za-z0-9_-]*", "use letters, digits, '-' and '_' only", "letters, digits, '-', '_'"),
            "", "The suite a built-in experiment belongs to: `atlasnn suite NAME` runs every one of them."),
        Key("paper_experiment", String(), "", "The paper experiment whose printed numbers the tables show beside this "
            "run's (columns of the same name); empty: the experiment's own name, if the paper has it."),
        Key("kind", Choice(("short", "transfer")), None,
            "A short run trains every model on one interval; a transfer run trains on a short source "
            "interval, then transfers the network to a long target interval with the time scaling's γ frozen.",
            default_text='"transfer" if [source] is given, else "short"'),
        Key("system", Sub("system"), None, "The Hamiltonian system whose equations of motion the network solves.",
            missing="expected a table", default_text="required"),
        Key("network", Sub("network"), {}, "The network N(t; θ) of the trial solution ẑ(t) = z0 + f(t − t0; γ)·N(t; θ)."),
        Key("train", Sub("train"), {}, "Training settings of every interval (a stage's own train table overrides them key by key)."),
        Key("models", _MODELS_OR_NONE, ["hnn", "atlas_tanh", "atlas_exp"],
            "The models to train, e.g. hnn (HNN, f = 1 − e^(−t)), atlas_tanh (ATLAS-NN (tanh), f = tanh(m t)) and "
            "atlas_exp (ATLAS-NN (exp), f = (1 − e^(−αt))/(1 + β e^(−αt))); their scalings' names "
            "(exp_decay, tanh, rational_exp) are accepted for them. The list is atlasnn.nn.MODELS. An empty "
            "list (a short experiment with [march] only) trains the marched models alone."),
        Key("gamma_init", Sub("gamma_init", sparse=True), {},
            "Initial values of each model's time-scaling parameters γ (learned on the first interval)."),
        Key("interval", Sub("stage"), None, "The interval of a short run, [t0, T], and its training settings.",
            default_text="required for a short run"),
        Key("source", Sub("stage"), None, "The source interval of a transfer run, on which γ is learned.",
            default_text="required for a transfer run"),
        Key("target", Sub("stage"), None, "The target interval of a transfer run; it starts at the source's t0 and "
            "its network starts from the source's.", default_text="required for a transfer run"),
        Key("transfer", Sub("transfer"), {}, "How a transfer run carries the source model to the target."),
        Key("evaluation", Sub("evaluation"), {}, "Where the trained models are measured, and against which classical integrators."),
        Key("seeds", SeedList(MAX_SEED, MAX_SEEDS), [0], "Seeds of the network initialisation and the jitter: every model is "
            "trained once per seed (a list, or a count K for seeds 0 to K−1)."),
        Key("follows", TextTable("expected a table of strings (notes on paper vs release choices)"), {},
            "Notes saying which choices follow the paper and which the authors' release; kept with the results."),
        Key("march", Sub("march"), None, "Time-marching ATLAS-NN on the experiment's interval (a transfer run's "
            "target): the interval cut into windows, each trained from the previous window's end state, γ "
            "learned in the first (docs/METHOD.md); adds a column per model.", default_text="none"),
        Key("solve", Sub("solve"), None, "The solver of atlasnn.solve (docs/SOLVER.md) on the experiment's "
            "interval (a transfer run's target): no training; adds the column of its method (gauss, "
            "deterministic: every seed records one solution; collocation: each seed draws its own random "
            "features).", default_text="none"),
        Key("schemes", NameList(lambda: f"expected a non-empty list drawn from {list(SCHEME_NAMES)}", SCHEME_NAMES,
                                unique=True), None, "Which of the config's schemes run (short: the models on the "
            "interval; baseline, transfer: a transfer run's; march: [march]; solve: [solve]); e.g. a profile "
            "with schemes = [\"solve\"] runs the collocation solver alone.",
            default_text="every scheme the file's tables give"),
        Key("polish", Sub("polish"), None, "L-BFGS after Adam on every training whose errors are tabulated "
            "(short runs, targets, the baseline); none by default.", default_text="none"),
        Key("execution", Sub("execution"), {}, "How the trainings are run (not what they compute)."),
        Key("quality", Sub("quality"), {}, "The thresholds of the quality verdict's error-estimate rule."),
        Key("profile", String(r"[A-Za-z0-9_-]+", "use letters, digits, '-' and '_' only",
                              "letters, digits, '-', '_'"), "default",
            "The name of the settings this file holds as written (the paper's experiments: \"paper\"); "
            "recorded with the results."),
        Key("profiles", Profiles(), {}, "Named variants of the experiment, each a table of the keys above "
            "merged over the file by --profile NAME (e.g. [profiles.release]: the authors' release's settings).",
            default_text="none"),
        Key("quick", Variant(), None, "A smoke-test variant merged over the file by --quick: any of the keys "
            "above, typically far fewer epochs.", default_text="none: --quick then caps every epoch budget at "
            "300, evaluates on 200 points, draws SE-10 and marches at rtol >= 1e-3"),
    )),
    "system": TableSpec("A built-in system by name, or your own Hamiltonian written as an expression or as a "
                        "Python function in a file.", (
        Key("name", String(), None, "A built-in system (`atlasnn systems` lists them) or, with hamiltonian, "
            "a name for your own.", default_text="none", note=_builtin_systems),
        Key("hamiltonian", String(), None, "Your own Hamiltonian H(q, p) as an expression in the coordinates, "
            "momenta and params, e.g. \"p**2/2 - cos(q)\" (parsed, never run as Python).", default_text="none"),
        Key("python", String(), None, "Your own Hamiltonian as a Python function in a file, \"FILE.py:FUNCTION\" "
            "(the path relative to the config file; FUNCTION defaults to hamiltonian): H(q, p, **params) for q, p "
            "arrays of shape (d,), returning one number, JAX-traceable. The route for large systems (an expression "
            "costs one operation per term); the file is run as Python.", default_text="none"),
        Key("coordinates", NameList("expected a non-empty list of names"), [],
            "Names of the coordinates q of your own Hamiltonian.", default_text="required with hamiltonian"),
        Key("momenta", NameList("expected a non-empty list of names"), [],
            "Names of the momenta p of your own Hamiltonian, one per coordinate.",
            default_text="required with hamiltonian"),
        Key("separable", Bool(), False, "Whether H = T(p) + V(q), which the symplectic integrators need "
            "(checked for your own Hamiltonian)."),
        Key("params", NumberTable(), {}, "Values of named parameters of H (a built-in's, e.g. lam, or names "
            "used in your expression)."),
        Key("z0", NumberList(Number()), None, "The initial state z0 = (q, p) at t0, coordinates first.",
            default_text="the built-in's own"),
    )),
    "network": TableSpec("The fully connected network N(t; θ) from the time t to R^(2d).", _network_keys(
        50, 1.0, "higher initial frequencies of the sin network; 1 is PyTorch's init")),
    "march": TableSpec("Time-marching ATLAS-NN (atlasnn.training): windows [t_k, t_k+1], window k exact at its "
                       "own start z_k = the previous window's end state; by default each window's length is "
                       "chosen by its error estimate, as an adaptive ODE solver chooses its steps.", (
        Key("models", _MODEL_LIST, ["atlas_exp"],
            "The models marched (their initial γ from [gamma_init]); one column each, e.g. atlas_exp_march."),
        Key("window", LengthOrAuto(MAX_TIME), "auto", "\"auto\": each window's length chosen by its error "
            "estimate (retrained shorter when its local error exceeds rtol × the state's range, longer "
            "when there is room); or a number: the longest window, the interval cut into "
            "⌈(T − t0)/window⌉ equal windows."),
        Key("n_windows", Integer(1, 100_000), None, "The number of equal windows, instead of window.",
            default_text="none (window decides)"),
        Key("rtol", Number(low=0, high=1), 1e-5, "Adaptive windows: a window's local error estimate must stay "
            "below atol + rtol × the state's range (measured over the hard-problem suite: docs/SUITE.md)."),
        Key("atol", Number(low=0), 0.0, "Adaptive windows: the absolute part of the local tolerance."),
        Key("first_window", Number(low=0, low_open=True, high=MAX_TIME, pi=True), None, "Adaptive windows: "
            "the first window's length.", default_text="one period of the fastest linear mode at z0"),
        Key("min_window", Number(low=0, low_open=True, high=MAX_TIME, pi=True), None, "Adaptive windows: "
            "the shortest window (one that still fails there is kept and marked forced).",
            default_text="(T − t0)·1e-4"),
        Key("max_rejects", Integer(0, 1000), 8, "Adaptive windows: retrainings of one window at most."),
        Key("max_windows", Integer(1, 100_000), 10_000, "Windows in all at most, fixed or adaptive (a fixed window "
            "that cuts the interval into more is refused before training)."),
        Key("start", Choice(("initial", "previous", "features")), "initial", "Where window k ≥ 1 starts its "
            "network: the initial weights (measured best), the previous window's trained ones (the paper's "
            "transfer, window to window), or its hidden layers with a zeroed output layer."),
        Key("thaw", Bool(), False, "Keep γ trainable after the first window (false: frozen, as in the paper's transfer)."),
        Key("carry_adam", Bool(), True, "Start each window's Adam from the previous window's moments."),
        Key("network", Sub("march.network"), {}, "The marched models' network (its own: the defaults were measured "
            "for time-marching)."),
        Key("train", Sub("train", sparse=True), {}, "Each window's Adam training, key by key over the measured "
            "defaults (2 000 epochs, K = 100, lr 5e-3 cosine to 5e-5, Adam betas (0.9, 0.999), sigma 0.5, "
            "causal_eps 10, best_rule lowest, lam_reg 1); n_points and epochs are per window; [train] is not inherited."),
        Key("first_train", Sub("train", sparse=True), {}, "The first window's training, key by key over march.train "
            "(e.g. more epochs while γ is learned)."),
        Key("polish", Sub("polish"), {}, "The second phase of every window after Adam (default: "
            "Levenberg–Marquardt, method = \"lm\"; method = \"none\" turns it off)."),
    )),
    "solve": TableSpec("The solver of atlasnn.solve on the evaluation interval, nothing trained (docs/SOLVER.md): "
                       "the Gauss collocation (method = \"gauss\": ATLAS-NN's trial solution with a polynomial "
                       "network at the Gauss–Legendre nodes of every window; symplectic, order 2s) or the random-"
                       "feature collocation (method = \"collocation\": z_k + f(s)·W φ(s/h), W by Gauss–Newton).", (
        Key("method", Choice(("gauss", "collocation")), "gauss", "gauss (measured the faster and more accurate: "
            "docs/SOLVER.md) or collocation."),
        Key("rtol", Number(low=1e-16, high=1), None, "Relative part of each window's tolerance (gauss: its error "
            "along the window; collocation: its local error).", default_text="the solver's: 1e-11 (gauss), 1e-12"),
        Key("atol", Number(low=0, high=1), None, "Absolute part of each window's tolerance.",
            default_text="the solver's: 1e-13 (gauss), 1e-14"),
        Key("stages", Integer(1, 16), None, "gauss: s, the Gauss–Legendre nodes per window (order 2s).",
            default_text="12"),
        Key("steps", Choice(("constant", "adaptive")), None, "gauss: one window length, found at the start and "
            "only ever shortened (symplectic), or every window its own length.", default_text="constant"),
        Key("h", Number(low=0, low_open=True), None, "gauss: one window length throughout (the tolerance is then "
            "only checked).", default_text="from the tolerance"),
        Key("features", Integer(1, 1000), None, "collocation: M, the random features per window (2d·M unknowns "
            "per window).", default_text="20"),
        Key("points", Integer(1, 10_000), None, "collocation: P collocation nodes per window (at least features).",
            default_text="features + 4"),
        Key("scaling", Choice(("linear", "tanh", "rational_exp")), None, "collocation: the time scaling f of each "
            "window: f = s (measured the best there), or ATLAS-NN's tanh or rational-exp shape.",
            default_text="linear"),
        Key("safety", Number(low=0, low_open=True, high=1000), None, "The window's error estimate is multiplied by "
            "this before the test.", default_text="2 (gauss), 3 (collocation)"),
    )),
    "march.network": TableSpec("The network of the marched models.", _network_keys(
        48, 4.0, "measured: 3–8 lowers a window's error 2–9×")),
    "polish": TableSpec("A second phase after Adam on fixed collocation times: Levenberg–Marquardt (damped "
                        "Gauss–Newton, Jacobian by autodiff) or L-BFGS (optax.lbfgs, zoom line search); either "
                        "keeps the best parameters, so it never makes a model worse.", (
        Key("method", Choice(("lm", "lbfgs", "none")), "lm", "lm (measured the fastest way to a low loss: "
            "docs/ESTIMATE.md), lbfgs, or none."),
        Key("steps", Integer(1, MAX_EPOCHS), None, "Step budget (LM trials, or L-BFGS steps).",
            default_text="150 (lm), 1000 (lbfgs)"),
        Key("n_points", Integer(2, MAX_POINTS), None, "Fixed collocation times (lm: Chebyshev–Lobatto; lbfgs: "
            "uniform).", default_text="lm: about 16 per unit of time, 32 to 100, at most ~600 residuals, and in a "
            "march never fewer than an earlier window had; lbfgs: 400"),
        Key("memory", Integer(1, 1000), 20, "lbfgs: curvature pairs kept."),
        Key("patience", Integer(1, MAX_EPOCHS), None, "Stop when the loss has not dropped by 0.1 % in this many "
            "steps.", default_text="20 (lm), 100 (lbfgs)"),
        Key("precision", Choice(("model", "float64", "mixed")), "model", "The phase's float type: the model's, a "
            "float64 copy rounded back, or (lm) float64 residuals with a float32 Jacobian."),
    )),
    "train": TableSpec("Adam on the physics loss L = residual of Hamilton's equations + λ_reg·energy "
                       "penalty, at K jittered collocation times.", (
        Key("epochs", Integer(1, MAX_EPOCHS), 10_000, "Epoch budget: Adam updates on this interval (fewer if "
            "the loss reaches the tolerance)."),
        Key("lr", Number(low=0, low_open=True), 1e-3, "Adam's learning rate."),
        Key("betas", NumberList(Number(low=0, high=0.999999999), 2, "expected two numbers [beta1, beta2]"),
            [0.9, 0.999], "Adam's decay rates (β1, β2); the authors' release used (0.999, 0.9999).",
            note=lambda: "2 numbers, each in [0, 1)"),
        Key("lam_reg", Number(low=0), 1.0, "λ_reg, the weight of the energy penalty (1/K)·Σ(H(ẑ(t_n)) − E0)² in the loss."),
        Key("n_points", Integer(2, MAX_POINTS), 200, "K, the number of collocation times t_n on the interval."),
        Key("sigma", Number(low=0), None, "The jitter σ: every epoch each t_n moves by Δt·σ·ε, ε ~ N(0, 1), Δt "
            "the grid spacing (reflected back into the interval).", default_text="0, or sigma_per_T·T"),
        Key("sigma_per_T", Number(low=0), None, "σ as a multiple of the interval end T (σ = value·T, the "
            "release's convention); give sigma or sigma_per_T, not both.", default_text="none"),
        Key("tolerance", Number(low=0), None, "Stop as soon as the loss L <= tolerance, keeping that epoch's "
            "parameters.", default_text="none (train the whole budget)"),
        Key("best_rule", Choice(BEST_RULES), "release", "Which parameters a run returns at the end of its budget: "
            "release (the lowest-loss ones after best_start_fraction of the budget), lowest (lowest loss in the "
            "whole run), last, or release_exact (the authors' release to the letter: the parameters after the "
            "update of the best epoch past the fraction, a running threshold starting at 1, and a strict "
            "loss < tolerance test)."),
        Key("best_start_fraction", Number(low=0, high=1), 0.8, "Fraction of the budget after which the release "
            "rules look for the lowest loss."),
        Key("lr_schedule", Choice(LR_SCHEDULES), "constant", "The learning rate over the epoch budget: constant, "
            "or a cosine or exponential decay (Optax schedules) from lr to lr·lr_final_ratio."),
        Key("lr_final_ratio", Number(low=0, low_open=True, high=1), 0.01, "With a decaying lr_schedule, the "
            "learning rate at the end of the budget as a fraction of lr."),
        Key("causal_eps", Number(low=0), 0.0, "Causal weighting of the loss (Wang, Sankaran & Perdikaris, 2022): "
            "each collocation time's loss is weighted by exp(−ε·∫ loss before it); 0 turns it off."),
        Key("release_fixed_point", Bool(), False, "Pin one collocation time at t0 + 1 every epoch, as the "
            "authors' release does (its third point is set to −1 and reflected)."),
        Key("chunk", Integer(1, MAX_EPOCHS), 1000, "Epochs per compiled call: progress is shown, and an interrupt "
            "saves the training state, between chunks."),
    )),
    "stage": TableSpec("An interval [t0, T] and the training settings used on it.", (
        Key("t0", _STAGE_TIME, 0.0, "Start of the interval, where the trial solution equals z0 exactly."),
        Key("T", _STAGE_TIME, None, "End of the interval (greater than t0).",
            missing="missing (the end of the interval)", default_text="required"),
        Key("train", Sub("train", sparse=True), {}, "Training settings for this interval only, overriding [train] key by key."),
    )),
    "transfer": TableSpec("Source → target: the target model starts from the source's weights and γ.", (
        Key("thaw", Bool(), False, "Train γ on the target too (the paper's future work); false keeps γ frozen, as in the paper."),
        Key("carry_adam", Bool(), True, "Start the target's Adam from the source's moments, as the authors' release does."),
        Key("baseline", Bool(), True, "Also train an HNN from scratch on the target, the paper's baseline."),
        Key("lr_from_source", Bool(), False, "Train the target at the source's learning rate instead of the "
            "target's own, as the authors' release did in effect (loading the source's Adam state also set "
            "its learning rate)."),
    )),
    "quality": TableSpec("The verdict on each training: judged first by its a-posteriori error estimate (the "
                         "linearised error equation along ẑ, no reference needed), as a fraction of the state's "
                         "range (the largest max − min of a component).", (
        Key("estimate_suspect", Number(low=0, low_open=True, high=1), 1e-2, "Suspect from this estimated max "
            "error / range (a true error above 5 % gives at least 1.7 % here: docs/ESTIMATE.md)."),
        Key("estimate_failed", Number(low=0, low_open=True, high=10), 5e-2, "Failed from this estimated max "
            "error / range (give it ≥ estimate_suspect)."),
    )),
    "execution": TableSpec("How the trainings are run; results do not depend on these beyond rounding.", (
        Key("seed_batch", CountOrAuto(1024), "auto", "Seeds of one model trained together as one compiled "
            "program: a number, or auto (batch where it measures faster; --seed-batch overrides it)."),
        Key("scheduler", String(), "", "The address of a Dask scheduler whose workers run the trainings "
            "(e.g. \"tcp://host:8786\"; docs/SCALE.md); empty: local processes. --scheduler and "
            "$ATLASNN_SCHEDULER override it."),
    )),
    "evaluation": TableSpec("Errors against a reference solution (SciPy DOP853, float64) on an evaluation grid.", (
        Key("eval_points", Integer(2, MAX_POINTS), None, "Number of equally spaced times of the evaluation grid.",
            default_text="K, the interval's n_points"),
        Key("se_steps", Integer(1, MAX_STEPS), None, "Steps of the symplectic Euler (SE) baseline of the tables.",
            default_text="K − 1"),
        Key("fine_factor", Integer(1, MAX_STEPS), 100, "The figures' fine SE takes se_steps × fine_factor steps "
            "(SE-100 for the oscillator, SE-10 for Hénon–Heiles)."),
        Key("integrators", NameList("expected a list of names", _integrators, nonempty=False), [],
            "More classical integrators to tabulate beside SE."),
        Key("reference_rtol", Number(low=0, low_open=True, high=1e-6), 1e-12, "Relative tolerance of the reference solution."),
        Key("reference_atol", Number(low=0, low_open=True, high=1e-6), 1e-12, "Absolute tolerance of the reference solution."),
        Key("work_precision", Bool(), False, "Also measure the classical methods' cost against accuracy on the same "
            "grid (symplectic Euler, Störmer–Verlet, Yoshida-4 at several step counts, DOP853 at several "
            "tolerances) beside each network's training time: results.json and figures/work_precision.png."),
    )),
}


def _gamma_tables() -> dict[str, TableSpec]:
    """[gamma_init] and one sub-table per registered model, from the model registry."""
    keys, out = [], {}
    for kind in MODELS.values():
        formula = kind.scaling.formula
        meaning = f"{kind.label}: {formula}." if kind.gamma_names else f"{kind.label}'s scaling {formula} has no γ."
        keys.append(Key(kind.name, Sub(f"gamma_init.{kind.name}"), {}, meaning))
        also = ", ".join(a for a in kind.aliases if a != kind.name)
        out[f"gamma_init.{kind.name}"] = TableSpec(
            f"{kind.label}" + (f" (also spelt {also})" if also else "") + ("." if kind.gamma_names else ": no γ."),
            tuple(Key(g, _GAMMA, 1.0, f"Initial {g} of {formula}.") for g in kind.gamma_names), sparse=True)
    out["gamma_init"] = TableSpec("Initial γ per model; a γ left out starts at 1.0, as in the paper.", tuple(keys),
                                  aliases=_model_spellings(), sparse=True)
    return out


class _Schema(Mapping):
    """Every table by id: the static tables above, a bundle or inverse file's
    (:mod:`._family_schema`, its top level ``"family"``) and the [gamma_init] tables of the models
    registered now (so a model registered at run time is configurable at once)."""

    def _all(self) -> dict[str, TableSpec]:
        return {**_STATIC_TABLES, **FAMILY_TABLES, **_gamma_tables()}

    def __getitem__(self, table: str) -> TableSpec:
        if table in _STATIC_TABLES:
            return _STATIC_TABLES[table]
        if table in FAMILY_TABLES:
            return FAMILY_TABLES[table]
        return _gamma_tables()[table]

    def __iter__(self):
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())


SCHEMA: Mapping[str, TableSpec] = _Schema()


def table_id(path: str) -> str:
    """The ``SCHEMA`` id of the table at a dotted path ("" the top level): "interval.train" -> "train"."""
    tid = ""
    for part in [p for p in path.split(".") if p]:
        spec = SCHEMA[tid]
        typ = spec.key(spec.aliases.get(part, part)).type
        tid = typ.table if isinstance(typ, Sub) else ""  # [quick] has the top level's keys
    return tid


def key_spec(path: str) -> Key:
    """The declaration of the key at a dotted path, e.g. ``key_spec("interval.train.lr")``."""
    table, _, name = path.rpartition(".")
    return SCHEMA[table_id(table)].key(name)
