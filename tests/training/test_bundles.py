"""Bundles: ẑ(t; z0, λ) over a box of initial states and parameters (nn, solutions, training,
checkpoint), and the parametric Hamiltonians they need (systems)."""

from __future__ import annotations

import numpy as np
import pytest

from atlasnn.checkpoint import load_bundle, save_bundle
from atlasnn.errors import AtlasError, ConfigError
from atlasnn.evaluation import reference_members, reference_solution
from atlasnn.systems import BundleBox, HamiltonianSystem, builtin_system, expression_system, with_params
from atlasnn.training import BundleTrainConfig, train_bundle

# the module's fixture trains for a quarter to half a minute: the long tier
pytestmark = pytest.mark.long

OSC = builtin_system("nonlinear_oscillator")


@pytest.fixture(scope="module")
def small_bundle():
    box = BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=2.0)
    cfg = BundleTrainConfig(windows=2, epochs=1000, chunk=500, lm_steps=30, lm_points=128)
    return train_bundle(OSC, box, cfg, width=16, seed=3)


def test_parametric_matches_fixed_hamiltonian():
    pend = expression_system("p**2/2 - g*cos(x)", ["x"], ["p"], {"g": 2.0}, z0=[1.0, 0.0])
    for system in (OSC, builtin_system("henon_heiles"), pend):
        z = np.random.default_rng(0).normal(size=(6, system.state_dim))
        theta = np.tile(system.param_vector(), (6, 1))
        energy, field = system.field_at(z, theta)
        np.testing.assert_allclose(energy, system.energy(z), rtol=1e-6)
        np.testing.assert_allclose(field, system.vector_field(z), rtol=1e-5, atol=1e-6)
        name = system.param_names[0]
        other = with_params(system, **{name: 0.5})
        assert other.params[name] == 0.5 and np.array_equal(other.z0, system.z0)
        np.testing.assert_allclose(other.energy(z), system.energy_at(z, theta * 0 + 0.5), rtol=1e-6)


def test_system_without_parametric_form_is_refused():
    plain = HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + q[0] ** 2 / 2, 1, params={"k": 1.0}, z0=[1.0, 0.0])
    box = BundleBox.around([1.0, 0.0], 0.1, {"k": (0.5, 2.0)}, T=1.0)
    with pytest.raises(AtlasError, match="parameters as an input"):
        box.check_system(plain)


@pytest.mark.parametrize("make, match", [
    (lambda: BundleBox((1.0, 1.0), (1.0, 1.0), 2.0), "zero width"),
    (lambda: BundleBox((1.0, 1.0), (1.2, 1.2), 2.0, {"lam": (1.0, 1.0)}), "zero width"),
    (lambda: BundleBox((1.0, 1.0), (0.5, 1.2), 2.0), "above high"),
    (lambda: BundleBox((1.0, 1.0), (1.2, 1.2), 0.0), "after t0"),
    (lambda: BundleBox((1.0,), (1.2,), 1.0), "2d entries"),
])
def test_bad_boxes_are_one_line_errors(make, match):
    with pytest.raises(ConfigError, match=match) as info:
        make()
    assert "\n" not in str(info.value)


def test_unknown_bundle_parameter_is_named():
    box = BundleBox.around([1.3, 1.0], 0.2, {"mu": (0.5, 1.5)}, T=1.0)
    with pytest.raises(ConfigError, match="'mu' is not a parameter"):
        box.check_system(OSC)


def test_every_member_starts_exactly_at_its_z0(small_bundle):
    sol = small_bundle.solution
    z, lam = sol.box.draw(np.random.default_rng(1), 50)
    out = sol(np.asarray([0.0, 0.5]), z, lam)
    assert np.array_equal(out[:, 0], z.astype(np.float32))  # f(0) = 0: exact in the model's float type
    assert np.abs(out[:, 1] - z).max() > 1e-3  # and it moves


def test_bundle_learns_the_flow(small_bundle):
    """A small, briefly trained bundle is already close to the references (100x closer than standing still)."""
    sol = small_bundle.solution
    z, lam = sol.box.draw(np.random.default_rng(2), 6)
    t = np.linspace(0, 2.0, 21)
    ref = reference_members(OSC, sol.box, z, lam, t)
    err = np.abs(sol(t, z, lam) - ref).max()
    still = np.abs(z[:, None, :] - ref).max()
    assert err < 0.02 * still, (err, still)  # measured: 6.7e-3 against 3.5


def test_windows_join_continuously(small_bundle):
    sol = small_bundle.solution
    z, lam = sol.box.draw(np.random.default_rng(3), 5)
    edge = sol.edges[1]
    out = sol(np.asarray([edge - 1e-6, edge]), z, lam)
    assert np.abs(out[:, 0] - out[:, 1]).max() < 1e-4


def test_reference_members_agree_with_reference_solution():
    box = BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=3.0)
    z, lam = box.draw(np.random.default_rng(4), 3)
    t = np.linspace(0, 3, 11)
    got = reference_members(OSC, box, z, lam, t)
    for i in range(3):
        want = reference_solution(with_params(OSC, lam=float(lam[i, 0])), z[i], t)
        np.testing.assert_allclose(got[i], want, atol=1e-9)


def test_sensitivities_match_finite_differences(small_bundle):
    sol = small_bundle.solution
    z, lam = sol.box.draw(np.random.default_rng(5), 2)
    t = np.linspace(0.1, 2.0, 5)
    dz, dl = sol.sensitivities(t, z, lam)
    assert dz.shape == (2, 5, 2, 2) and dl.shape == (2, 5, 2, 1)
    h = 1e-2
    for j in range(2):
        up, down = z.copy(), z.copy()
        up[:, j] += h
        down[:, j] -= h
        fd = (sol(t, up, lam) - sol(t, down, lam)) / (2 * h)
        np.testing.assert_allclose(dz[..., j], fd, atol=2e-3)
    fd = (sol(t, z, lam + h) - sol(t, z, lam - h)) / (2 * h)
    np.testing.assert_allclose(dl[..., 0], fd, atol=2e-3)


def test_checkpoint_round_trip_is_bit_identical(small_bundle, tmp_path):
    sol = small_bundle.solution
    path = tmp_path / "bundle.npz"
    save_bundle(path, sol, extra={"note": "test"})
    loaded = load_bundle(path)
    z, lam = sol.box.draw(np.random.default_rng(6), 7)
    t = np.linspace(0, 2.0, 9)
    assert np.array_equal(loaded(t, z, lam), sol(t, z, lam))
    assert loaded.system.name == OSC.name and loaded.box.describe() == sol.box.describe()
    (tmp_path / "bad.npz").write_bytes(path.read_bytes()[:-100])
    with pytest.raises(AtlasError, match="bad.npz"):
        load_bundle(tmp_path / "bad.npz")


def test_member_shape_errors(small_bundle):
    sol = small_bundle.solution
    with pytest.raises(ConfigError, match="shape"):
        sol(np.asarray([0.0]), np.zeros((3, 3)), np.zeros((3, 1)))
    with pytest.raises(ConfigError, match="lam"):
        sol(np.asarray([0.0]), np.zeros((3, 2)), np.zeros((3, 2)))


@pytest.mark.slow  # over a minute on the 2-core machine: run with -m slow (CI stays under 30 min)
def test_run_command_trains_a_bundle_from_a_config(tmp_path):
    """`atlasnn run` on a config with [bundle]: a checkpoint per seed, held-out errors against the
    references, the figures, and a --quick that caps the budget."""
    import json

    from atlasnn.cli import main

    toml = tmp_path / "b.toml"
    toml.write_text('name = "b"\nseeds = [0, 1]\n[system]\nname = "nonlinear_oscillator"\n[bundle]\nmethod = "network"\nT = 1.0\n'
                    'ranges = { lam = [0.8, 1.2] }\nwindows = 2\nwidth = 8\nepochs = 400\nlm_steps = 5\n'
                    'lm_points = 32\ntest_members = 6\ntest_times = 11\n')
    out = tmp_path / "run"
    assert main(["run", str(toml), "--quick", "--out", str(out)]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["kind"] == "bundle" and res["quick"] and set(res["seeds"]) == {"0", "1"}
    for seed in ("0", "1"):
        rec = res["seeds"][seed]
        assert len(rec["test"]["per_member"]) == 6 and rec["test"]["worst"] >= rec["test"]["median"] > 0
        assert rec["initial_state_error"] == 0.0 and len(rec["final_loss"]) == 2
        assert load_bundle(out / "models" / f"bundle_seed{seed}.npz").box.params == {"lam": (0.8, 1.2)}
    assert (out / "figures" / "bundle_map.png").is_file() and (out / "figures" / "bundle_errors.png").is_file()
    assert "QUICK" in (out / "summary.md").read_text().upper()


@pytest.mark.slow  # 28 s; the family runner's resume is checked by test_fit_door's interrupted family run (CI stays under 30 min)
def test_an_interrupted_bundle_run_resumes_from_the_seeds_it_finished(tmp_path, monkeypatch):
    """A bundle run interrupted after seed 0 keeps it (its record, its errors, its checkpoint) and
    `family --resume` trains seed 1 only; before, there was no --resume."""
    import json

    import atlasnn.experiments._family_run as family_run
    from atlasnn.cli import main

    toml = tmp_path / "b.toml"
    toml.write_text('name = "b"\nseeds = [0, 1]\n[system]\nname = "nonlinear_oscillator"\n[bundle]\nmethod = "network"\nT = 1.0\n'
                    'ranges = { lam = [0.8, 1.2] }\nwidth = 8\nepochs = 200\nlm_steps = 0\n'
                    'test_members = 6\ntest_times = 11\n')
    out, real, trained = tmp_path / "run", family_run._bundle_seed, []

    def seed_1_interrupted(cfg, test, out, say, seed):
        if seed == 1:
            raise KeyboardInterrupt
        trained.append(seed)
        return real(cfg, test, out, say, seed)

    monkeypatch.setattr(family_run, "_bundle_seed", seed_1_interrupted)
    assert main(["family", str(toml), "--out", str(out), "--no-progress"]) == 130
    kept = json.loads((out / "partial" / "seed0.json").read_text())["record"]
    monkeypatch.setattr(family_run, "_bundle_seed", lambda *a: (trained.append(a[-1]), real(*a))[1])
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0  # `run` resumes it as `family` does
    res = json.loads((out / "results.json").read_text())
    assert trained == [0, 1] and res["seeds"]["0"]["test"] == kept["test"] and set(res["seeds"]) == {"0", "1"}
    assert (out / "figures" / "bundle_errors.png").is_file() and (out / "models" / "bundle_seed1.npz").is_file()


@pytest.mark.parametrize("kw, match", [({"members": "corners"}, "members"), ({"retry_factor": 0.5}, "retry_factor"),
                                       ({"windows": 0}, "windows"), ({"epochs": 0, "lm_steps": 0}, "epochs > 0"),
                                       ({"lm_rounds": 0}, "lm_rounds")])
def test_bundle_train_config_errors(kw, match):
    with pytest.raises(ConfigError, match=match):
        BundleTrainConfig(**kw)


def test_edge_sampling_crowds_the_faces():
    """Half the members of a draw come from the arcsine law: more points near the box's faces than
    a uniform draw puts there (a uniform draw has 10 % of its points in the outer 5 % of each side)."""
    import jax

    from atlasnn.training._bundle import _draw

    box = BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=1.0)
    _, _, lam = _draw(jax.random.PRNGKey(0), box, 20000, np.float32, 0.0, 1.0, "edges")
    _, _, lam_u = _draw(jax.random.PRNGKey(0), box, 20000, np.float32, 0.0, 1.0, "uniform")
    near = lambda v: float(np.mean((np.asarray(v) < 0.55) | (np.asarray(v) > 1.45)))  # noqa: E731
    assert near(lam) > 0.17 and abs(near(lam_u) - 0.10) < 0.01  # expected 0.19 and 0.10
    assert float(np.min(lam)) >= 0.5 and float(np.max(lam)) <= 1.5


def test_lm_rounds_draw_fresh_points_and_record_every_trial():
    """LM split into rounds: every trial is in the history (the start and 12 trials, not one start
    per round), and the later rounds fit other points, so the model differs from one fixed set's."""
    cfg = dict(windows=1, epochs=20, chunk=20, lm_steps=12, lm_points=48)
    one = train_bundle(OSC, BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=1.0),
                       BundleTrainConfig(**cfg), width=8, seed=1)
    four = train_bundle(OSC, BundleBox.around([1.3, 1.0], 0.2, {"lam": (0.5, 1.5)}, T=1.0),
                        BundleTrainConfig(**cfg, lm_rounds=4), width=8, seed=1)
    for trained in (one, four):
        assert trained.lm_loss[0].size == 13 or trained.lm_stop[0] != "budget"
        assert np.all(np.isfinite(trained.lm_loss[0]))
    np.testing.assert_array_equal(one.adam_loss[0], four.adam_loss[0])  # the same up to LM
    assert not np.array_equal(np.asarray(one.solution.windows[0].weights[0]),
                              np.asarray(four.solution.windows[0].weights[0]))
