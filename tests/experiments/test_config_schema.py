"""The schema-driven config parser: messages kept byte for byte, both model spellings, and the
schema agreeing with the dataclasses and scalings it describes."""

import copy
import dataclasses
import re
import tomllib

import numpy as np
import pytest

from atlasnn.errors import ConfigError
from atlasnn.experiments.config import (
    EvaluationConfig,
    SystemConfig,
    TrainSettings,
    builtin_config_path,
    load_config,
    parse_config,
)
from atlasnn.experiments import table_columns
from atlasnn.experiments.config import SCHEMA, key_spec
from atlasnn.nn import MODELS, make_model, make_scaling
from atlasnn.training import TrainConfig


def raw(name):
    return tomllib.loads(builtin_config_path(name).read_text())


EXPR = {"hamiltonian": "p**2/2 - cos(q)", "coordinates": ["q"], "momenta": ["p"], "separable": True, "z0": [1.0, 0.0]}

# One bad value each, on oscillator-short ("short") or oscillator-transfer ("transfer"), and the
# message the hand-written parser gave before the schema (recorded from it): kept byte for byte.
MESSAGES = [
    ('short', lambda d: d.update(bogus=1),
     "bogus = 1: unknown key (known: ['description', 'evaluation', 'follows', 'gamma_init', 'interval', 'kind', 'models', 'name', 'network', 'quick', 'seeds', 'source', 'system', 'target', 'train', 'transfer'])"),
    ('short', lambda d: d.update(name='a b'),
     "name = 'a b': use letters, digits, '-', '_' and '.' only"),
    ('short', lambda d: d.update(name=3),
     'name = 3: expected a string'),
    ('short', lambda d: d.update(kind='long'),
     "kind = 'long': must be one of ['short', 'transfer']"),
    ('short', lambda d: d.update(description=1),
     'description = 1: expected a string'),
    ('short', lambda d: d['train'].update(lr=0.0),
     'train.lr = 0.0: must be > 0'),
    ('short', lambda d: d['train'].update(lr=float('nan')),
     'train.lr = nan: must be finite'),
    ('short', lambda d: d['train'].update(lr='fast'),
     "train.lr = 'fast': expected a number"),
    ('short', lambda d: d['train'].update(epochs=2.5),
     'train.epochs = 2.5: expected an integer'),
    ('short', lambda d: d['train'].update(epochs=1e20),
     'train.epochs = 100000000000000000000: must be <= 1000000000'),
    ('short', lambda d: d['train'].update(epochs=True),
     'train.epochs = True: expected an integer'),
    ('short', lambda d: d['train'].update(epoch=100),
     "train.epoch = 100: unknown key (known: ['best_rule', 'best_start_fraction', 'betas', 'chunk', 'epochs', 'lam_reg', 'lr', 'n_points', 'sigma', 'sigma_per_T', 'tolerance'])"),
    ('short', lambda d: d['train'].update(betas=[0.9, 1.0]),
     'train.betas[1] = 1.0: must be <= 1'),
    ('short', lambda d: d['train'].update(betas=[0.9]),
     'train.betas = [0.9]: expected two numbers [beta1, beta2]'),
    ('short', lambda d: d['train'].update(betas=[-0.1, 0.9]),
     'train.betas[0] = -0.1: must be >= 0'),
    ('short', lambda d: d['train'].update(best_start_fraction=1.5),
     'train.best_start_fraction = 1.5: must be <= 1'),
    ('short', lambda d: d['train'].update(best_rule='median'),
     "train.best_rule = 'median': must be one of ['release', 'lowest', 'last', 'release_exact']"),
    ('short', lambda d: d['train'].update(sigma=0.1),
     'train.sigma = 0.1: give either sigma or sigma_per_T, not both'),
    ('short', lambda d: d['train'].update(n_points=10**7),
     'train.n_points = 10000000: must be <= 1000000'),
    ('short', lambda d: d['interval'].update(T=1e7),
     'interval.T = 10000000.0: must be <= 1e+06'),
    ('short', lambda d: d['interval'].update(T='pi/0'),
     "interval.T = 'pi/0': division by zero"),
    ('short', lambda d: d['interval'].update(T='four pi'),
     'interval.T = \'four pi\': expected a number or a multiple of pi such as "4*pi"'),
    ('short', lambda d: d['interval'].update(t0=1.0, T=1.0),
     'interval.T = 1.0: must be greater than t0 = 1'),
    ('short', lambda d: d['interval'].update(T=1e-300),
     'interval.T = 1e-300: [0, 1e-300] is too short for 200 distinct collocation times in float32 (spacing 5.03e-303); lengthen the interval or lower n_points'),
    ('short', lambda d: d['interval'].pop('T'),
     'interval.T = None: missing (the end of the interval)'),
    ('short', lambda d: d['interval'].update(bogus=1),
     "interval.bogus = 1: unknown key (known: ['T', 't0', 'train'])"),
    ('short', lambda d: d['interval'].update(train={'lr': -1}),
     'interval.train.lr = -1.0: must be > 0'),
    ('short', lambda d: d['interval'].update(train=5),
     'interval.train = 5: expected a table'),
    ('short', lambda d: d.pop('interval'),
     'interval = None: missing: a short experiment needs [interval] with T'),
    ('short', lambda d: d.update(source={'T': 1.0}),
     'source = \'...\': only a transfer experiment (kind = "transfer") has source and target'),
    ('short', lambda d: d.update(interval=5),
     'interval = 5: expected a table'),
    ('short', lambda d: d['network'].update(width=0),
     'network.width = 0: must be >= 1'),
    ('short', lambda d: d['network'].update(depth=101),
     'network.depth = 101: must be <= 100'),
    ('short', lambda d: d['network'].update(activation='relu'),
     "network.activation = 'relu': must be one of ['silu', 'sin', 'softplus', 'tanh']"),
    ('short', lambda d: d.update(network=[]),
     'network = []: expected a table'),
    ('short', lambda d: d['system'].update(name='lorenz'),
     "system.name = 'lorenz': unknown system; built-ins are ['fput', 'harmonic_oscillator', 'henon_heiles', 'nls', 'nonlinear_oscillator', 'sine_gordon'] (or give system.hamiltonian as an expression)"),
    ('short', lambda d: d['system'].update(name=5),
     'system.name = 5: expected a string'),
    ('short', lambda d: d['system'].update(z0=[1.0]),
     "system: system.z0 must have 2 components ['x', 'p'], got 1"),
    ('short', lambda d: d['system'].update(z0=[1.0, 'x']),
     "system.z0[1] = 'x': expected a number"),
    ('short', lambda d: d['system'].update(z0=[]),
     'system.z0 = []: expected a list of numbers'),
    ('short', lambda d: d['system'].update(z0=[-1.0e200, 0.0]),
     'system.z0 = [-1e+200, 0.0]: the Hamiltonian or its gradient is not finite there with params {\'lam\': 1.0} (H = inf, J∇H = [0.0, inf])'),
    ('short', lambda d: d['system'].update(params={'lam': 'big'}),
     "system.params.lam = 'big': expected a number"),
    ('short', lambda d: d['system'].update(params={'la m': 1.0}),
     "system.params['la m'] = 1.0: parameter names must be identifiers"),
    ('short', lambda d: d['system'].update(params=3),
     'system.params = 3: expected a table of numbers'),
    ('short', lambda d: d['system'].update(params={'omega': 1.0}),
     "system: bad parameters for system 'nonlinear_oscillator': nonlinear_oscillator() got an unexpected keyword argument 'omega'"),
    ('short', lambda d: d['system'].update(separable='yes'),
     "system.separable = 'yes': expected true or false"),
    ('short', lambda d: d['system'].update(bogus=1),
     "system.bogus = 1: unknown key (known: ['coordinates', 'hamiltonian', 'momenta', 'name', 'params', 'separable', 'z0'])"),
    ('short', lambda d: d['system'].pop('name'),
     "system = {'params': {'lam': 1.0}, 'z0': [1.3, 1.0]}: give a built-in system name or a hamiltonian expression"),
    ('short', lambda d: d.pop('system'),
     'system = None: expected a table'),
    ('short', lambda d: d.update(system=EXPR | {'z0': [1.0, 0.0, 0.0]}),
     "system.z0 = [1.0, 0.0, 0.0]: must have 2 components ['q', 'p']"),
    ('short', lambda d: d.update(system=EXPR | {'momenta': ['p', 'r']}),
     "system.momenta = ['p', 'r']: must have as many names as system.coordinates (1)"),
    ('short', lambda d: d.update(system=EXPR | {'coordinates': []}),
     'system.coordinates = []: expected a non-empty list of names'),
    ('short', lambda d: d.update(system={k: v for k, v in EXPR.items() if k != 'momenta'}),
     'system.momenta = None: expected a non-empty list of names'),
    ('short', lambda d: d.update(system=EXPR | {'hamiltonian': 'p**2/2 + q*p'}),
     'system.separable = True: the Hamiltonian is not separable (d²H/dq dp = 1 at [1.0, 0.0]); set separable = false'),
    ('short', lambda d: d.update(system=EXPR | {'hamiltonian': 'log(q) + p**2', 'z0': [-1.0, 0.0]}),
     'system.z0 = [-1.0, 0.0]: the Hamiltonian or its gradient is not finite there (H = nan, J∇H = [0.0, 1.0])'),
    ('short', lambda d: d.update(system=EXPR | {'hamiltonian': '__import__("os").system("x")'}),
     'system: attribute access \'.system\' is not allowed in an expression (at column 1: \'__import__("os").system\')'),
    ('short', lambda d: d.update(models=[]),
     "models = []: give at least one model (an empty list needs a short experiment with a [march] table, "
     "or a [solve] table)"),
    ('short', lambda d: d.update(schemes=['solve']),
     "schemes = ['solve']: solve needs a [solve] table"),
    ('short', lambda d: d.update(schemes=['leapfrog']),
     "schemes[0] = 'leapfrog': must be one of ['baseline', 'short', 'transfer', 'march', 'solve']"),
    ('short', lambda d: d.update(solve={'rtol': 0.0}),
     'solve.rtol = 0.0: must be >= 1e-16'),
    ('short', lambda d: d.update(solve={'method': 'collocation', 'features': 30, 'points': 20}),
     'solve.points = 20: must be at least solve.features (30): fewer points cannot determine the output weights'),
    ('short', lambda d: d.update(models='hnn'),
     "models = 'hnn': expected a list drawn from ['atlas_exp', 'atlas_tanh', 'hnn']"),
    ('short', lambda d: d.update(models=['hnn', 'hnn']),
     "models = ['hnn', 'hnn']: names must not repeat"),
    ('short', lambda d: d.update(models=['hnn', 'atlas_cosh']),
     "models[1] = 'atlas_cosh': must be one of ['atlas_exp', 'atlas_tanh', 'hnn']"),
    ('short', lambda d: d.update(models=[1]),
     'models[0] = 1: expected a string'),
    ('short', lambda d: d['gamma_init'].update(atlas_cosh={'m': 1.0}),
     "gamma_init.atlas_cosh = {'m': 1.0}: unknown key (known: ['atlas_exp', 'atlas_tanh', 'hnn'])"),
    ('short', lambda d: d['gamma_init']['atlas_tanh'].update(m=0.0),
     'gamma_init.atlas_tanh.m = 0.0: must be > 0'),
    ('short', lambda d: d['gamma_init']['atlas_exp'].update(gamma=1.0),
     "gamma_init.atlas_exp.gamma = 1.0: unknown key (known: ['alpha', 'beta'])"),
    ('short', lambda d: d['gamma_init'].update(hnn={'m': 1.0}),
     'gamma_init.hnn.m = 1.0: unknown key (known: [])'),
    ('short', lambda d: d['gamma_init'].update(atlas_exp=1.0),
     'gamma_init.atlas_exp = 1.0: expected a table'),
    ('short', lambda d: d.update(gamma_init=[]),
     'gamma_init = []: expected a table'),
    ('short', lambda d: d['evaluation'].update(integrators=['rk4']),
     "evaluation.integrators[0] = 'rk4': must be one of ['stormer_verlet', 'symplectic_euler', 'yoshida4']"),
    ('short', lambda d: d['evaluation'].update(integrators='rk4'),
     "evaluation.integrators = 'rk4': expected a list of names"),
    ('short', lambda d: d['evaluation'].update(eval_points=1),
     'evaluation.eval_points = 1: must be >= 2'),
    ('short', lambda d: d['evaluation'].update(se_steps=0),
     'evaluation.se_steps = 0: must be >= 1'),
    ('short', lambda d: d['evaluation'].update(fine_factor=10**7),
     'evaluation.fine_factor = 10000000: the fine symplectic-Euler run would take 1990000000 steps (se_steps x fine_factor must be <= 100000000)'),
    ('short', lambda d: d['evaluation'].update(reference_rtol=1e-3),
     'evaluation.reference_rtol = 0.001: must be <= 1e-06'),
    ('short', lambda d: d['evaluation'].update(reference_atol=0.0),
     'evaluation.reference_atol = 0.0: must be > 0'),
    ('short', lambda d: d['evaluation'].update(bogus=0.0),
     "evaluation.bogus = 0.0: unknown key (known: ['eval_points', 'fine_factor', 'integrators', 'reference_atol', 'reference_rtol', 'se_steps'])"),
    ('short', lambda d: d.update(seeds=[4294967296]),
     'seeds[0] = 4294967296: must be <= 4294967295'),
    ('short', lambda d: d.update(seeds=[0, 0]),
     'seeds = [0, 0]: seeds must not repeat'),
    ('short', lambda d: d.update(seeds=0),
     'seeds = 0: must be >= 1'),
    ('short', lambda d: d.update(seeds=20000),
     'seeds = 20000: must be <= 10000'),
    ('short', lambda d: d.update(seeds=[]),
     'seeds = []: expected a list of integer seeds or a count'),
    ('short', lambda d: d.update(seeds=1.5),
     'seeds = 1.5: expected a list of integer seeds or a count'),
    ('short', lambda d: d.update(seeds=[-1]),
     'seeds[0] = -1: must be >= 0'),
    ('short', lambda d: d.update(follows={'a': 1}),
     "follows = {'a': 1}: expected a table of strings (notes on paper vs release choices)"),
    ('short', lambda d: d.update(follows=[]),
     'follows = []: expected a table of strings (notes on paper vs release choices)'),
    ('short', lambda d: d.update(transfer={'thaw': 1}),
     'transfer.thaw = 1: expected true or false'),
    ('short', lambda d: d.update(transfer={'bogus': 1}),
     "transfer.bogus = 1: unknown key (known: ['baseline', 'carry_adam', 'thaw'])"),
    ('transfer', lambda d: d.pop('target'),
     'target = None: missing: a transfer experiment needs [source] and [target] with T'),
    ('transfer', lambda d: d.update(interval={'T': 1.0}),
     "interval = '...': a transfer experiment uses [source] and [target], not [interval]"),
    ('transfer', lambda d: d['target'].update(t0=1.0),
     'target.t0 = 1.0: must equal source.t0 = 0 (same initial state)'),
    ('transfer', lambda d: d['transfer'].update(thaw='no'),
     "transfer.thaw = 'no': expected true or false"),
    ('transfer', lambda d: d['transfer'].update(carry_adam=None),
     'transfer.carry_adam = None: expected true or false'),
    ('transfer', lambda d: d['target'].update(T='2*pi', t0=0.0, train={'n_points': 1}),
     'target.train.n_points = 1: must be >= 2'),
    ('transfer', lambda d: d.update(kind='short'),
     'interval = None: missing: a short experiment needs [interval] with T'),
]


@pytest.mark.parametrize("base, edit, expected", MESSAGES, ids=[m[2].split(" = ")[0] + f"-{i}" for i, m in enumerate(MESSAGES)])
def test_messages_are_kept_byte_for_byte(base, edit, expected):
    d = copy.deepcopy(raw("oscillator-short" if base == "short" else "oscillator-transfer"))
    edit(d)
    with pytest.raises(ConfigError) as info:
        parse_config(d)
    msg = str(info.value)
    if " (known: [" in expected:  # a table's list of keys may grow; the names it had stay
        head, known = expected.split(" (known: ")
        assert msg.startswith(head + " (known: ["), msg
        old = set(re.findall(r"'([^']*)'", known))
        assert old <= set(re.findall(r"'([^']*)'", msg.split(" (known: ")[1])), msg
    else:
        assert msg == expected


def test_schema_parse_equals_the_paper_configs_resolution():
    """The four shipped configs resolve to the values their files give (spot checks of every table)."""
    cfg = load_config(builtin_config_path("oscillator-transfer"))
    assert cfg.source.train.lr == 8e-3 and cfg.target.train.lr == 5e-3  # stage over [train]
    assert cfg.source.train.epochs == 30000 and cfg.target.train.n_points == 500
    assert cfg.target.train.sigma_per_T == 0.03 and cfg.target.train.sigma is None
    assert cfg.evaluation.eval_points == 5000 and cfg.evaluation.se_steps is None
    assert cfg.evaluation.integrators == () and cfg.seeds == (0,)
    assert cfg.gamma_init == {"atlas_tanh": {"m": 1.0}, "atlas_exp": {"alpha": 1.0, "beta": 1.0}}
    assert cfg.system.coordinates == () and cfg.system.params == {"lam": 1.0}


def test_a_stage_sigma_clears_the_inherited_sigma_per_T():
    d = raw("oscillator-transfer")
    d["source"]["train"]["sigma"] = 2.0
    cfg = parse_config(d)
    assert cfg.source.train.sigma == 2.0 and cfg.source.train.sigma_per_T is None
    assert cfg.target.train.sigma is None and cfg.target.train.sigma_per_T == 0.03
    assert cfg.source.train.to_train_config(cfg.source.T, 0, False).sigma == 2.0


def test_settings_dataclasses_have_exactly_the_declared_keys_and_defaults():
    for cls, table in ((TrainSettings, "train"), (EvaluationConfig, "evaluation"), (SystemConfig, "system")):
        fields = {f.name: f for f in dataclasses.fields(cls)}
        assert list(fields) == [k.name for k in SCHEMA[table].keys]
        inst = cls()
        for k in SCHEMA[table].keys:
            expected = tuple(k.default) if isinstance(k.default, list) else k.default
            assert getattr(inst, k.name) == expected, (table, k.name)
    # every TrainConfig setting a config can give reaches the trainer
    tc = TrainSettings(epochs=7, lr=0.5, tolerance=1e-3, best_rule="last").to_train_config(3.0, seed=4, progress=False)
    assert (tc.epochs, tc.lr, tc.tolerance, tc.best_rule, tc.seed, tc.chunk) == (7, 0.5, 1e-3, "last", 4, 7)
    shared = {f.name for f in dataclasses.fields(TrainConfig)} & {f.name for f in dataclasses.fields(TrainSettings)}
    assert {"epochs", "lr", "betas", "lam_reg", "n_points", "sigma", "tolerance", "best_rule", "chunk"} <= shared


def test_gamma_keys_match_the_scalings():
    """gamma_init declares, per model, exactly its scaling's γ names, with the scaling's own default."""
    for model, kind in MODELS.items():
        keys = SCHEMA[f"gamma_init.{model}"].keys
        assert [k.name for k in keys] == list(kind.scaling.gamma_names)
        made = make_scaling(kind.scaling.name)
        for k in keys:
            assert float(np.asarray(made.gamma()[k.name])) == pytest.approx(k.default, rel=1e-6)
    aliases = SCHEMA["gamma_init"].aliases
    assert {kind.scaling.name for kind in MODELS.values()} <= set(aliases) and set(aliases.values()) == set(MODELS)


def test_key_spec_finds_declarations_through_shared_tables():
    assert key_spec("interval.train.lr") is key_spec("train.lr") is key_spec("source.train.lr")
    assert key_spec("target.T").missing == "missing (the end of the interval)"
    assert key_spec("gamma_init.atlas_exp.beta").default == 1.0
    assert key_spec("quick.train") is key_spec("train")


# ------------------------------------------------------------------ one model, two names
API_NAMES = {"hnn": "exp_decay", "atlas_tanh": "tanh", "atlas_exp": "rational_exp"}


def test_configs_accept_the_api_scaling_names_and_normalise_them():
    paper = raw("oscillator-short")
    api = copy.deepcopy(paper)
    api["models"] = [API_NAMES[m] for m in paper["models"]]
    api["gamma_init"] = {"tanh": {"m": 1.5}, "rational_exp": {"alpha": 2.0, "beta": 0.5}}
    paper["gamma_init"] = {"atlas_tanh": {"m": 1.5}, "atlas_exp": {"alpha": 2.0, "beta": 0.5}}
    a, b = parse_config(api), parse_config(paper)
    assert a == b  # everything resolved the same
    assert a.models == ("hnn", "atlas_tanh", "atlas_exp")
    assert table_columns(a) == ["se", "hnn", "atlas_tanh", "atlas_exp"]
    assert set(a.gamma_init) == {"atlas_tanh", "atlas_exp"}


def test_mixed_spellings_of_one_model_are_refused():
    d = raw("oscillator-short")
    d["models"] = ["hnn", "exp_decay"]
    with pytest.raises(ConfigError, match=r"^models = \['hnn', 'exp_decay'\]: names must not repeat$"):
        parse_config(d)
    d = raw("oscillator-short")
    d["gamma_init"]["tanh"] = {"m": 2.0}
    with pytest.raises(ConfigError) as info:
        parse_config(d)
    assert str(info.value) == "gamma_init.tanh = {'m': 2.0}: the same as gamma_init.atlas_tanh; give one of them"


@pytest.mark.parametrize("paper, api", sorted(API_NAMES.items()))
def test_python_api_accepts_both_names(paper, api):
    gamma = {"m": 0.7} if paper == "atlas_tanh" else {"alpha": 1.3, "beta": 0.4} if paper == "atlas_exp" else None
    s1, s2 = make_scaling(paper, gamma), make_scaling(api, gamma)
    assert type(s1) is type(s2) and s1.name == api
    m1 = make_model([1.0, 0.0], scaling=paper, gamma=gamma, width=4, seed=3)
    m2 = make_model([1.0, 0.0], scaling=api, gamma=gamma, width=4, seed=3)
    t = np.linspace(0.0, 2.0, 7)
    np.testing.assert_array_equal(np.asarray(m1(t)), np.asarray(m2(t)))


def test_an_unnamed_expression_system_takes_the_configs_name_in_its_messages():
    data = {"name": "my-well", "models": ["hnn"], "interval": {"T": 1.0},
            "system": {"hamiltonian": "p**2/2 + q**4/4", "coordinates": ["q"], "momenta": ["p"]}}
    with pytest.raises(ConfigError, match="system 'my-well' has no default initial state"):
        parse_config(data, source="w.toml")
    data["system"]["z0"] = [1.0, 0.0]
    assert parse_config(data, source="w.toml").system.build().name == "my-well"
