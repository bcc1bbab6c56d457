"""atlasnn.learn_hamiltonian: H_θ learned from trajectories through the solver and as an HNN —
a known form's parameters recovered, the trust rules (noise, held-out data, an early stop),
Ctrl-C keeping the best H, and bad input refused in one line before any training."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import atlasnn
from atlasnn import learn_hamiltonian
from atlasnn.inverse import HNN, ThroughSolver
from atlasnn.errors import ConfigError

pytestmark = pytest.mark.usefixtures("x64")  # float64 (tests/conftest.py)

TIMES = np.arange(0.0, 3.01, 0.1)


class Quadratic(eqx.Module):
    """H = a·p²/2 + b·q²/2: a known form with two unknown parameters."""

    a: jax.Array
    b: jax.Array

    def __call__(self, q, p):
        return self.a * p[0] ** 2 / 2 + self.b * q[0] ** 2 / 2


def _guess():
    return Quadratic(jnp.array(0.7), jnp.array(1.0))


def _trajectories(b=2.0, noise=0.0, starts=([1.0, 0.0], [0.0, 1.0])):
    """Oscillator orbits (a = 1) with Gaussian noise, observed every 0.1 over [0, 3]."""
    truth = atlasnn.HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + b * q[0] ** 2 / 2, 1)
    rng = np.random.default_rng(0)
    return [(TIMES, atlasnn.solve(truth, z, (0.0, 3.0))(TIMES) + noise * rng.standard_normal((TIMES.size, 2)))
            for z in starts]


@pytest.mark.long
def test_through_the_solver_recovers_a_known_form_and_flags_a_noise_claimed_too_small():
    """Noisy orbits of a = 1, b = 2: the parameters within 3 % and four standard errors; claiming a
    tenth of the true noise makes the loss far above the claimed noise's own, which the result says."""
    result = learn_hamiltonian(_guess(), _trajectories(noise=0.01), ThroughSolver(steps=150, rate=0.05), noise=0.001)
    assert abs(float(result.model.a) - 1.0) < 0.03 and abs(float(result.model.b) - 2.0) < 0.06
    # standard errors from the residuals' Jacobian through the Gauss core (forward mode): they cover the errors
    assert result.std is not None and np.all(np.abs(np.array([result.model.a, result.model.b]) - [1.0, 2.0])
                                             < 4 * result.std), result.std
    assert result.held_out_loss is not None and result.steps == 150 and result.stopped is None
    assert not result.trusted and "the noise's own" in result.notes[0]
    z = atlasnn.solve(result.system, [1.0, 0.0], (0.0, 2.0))(2.0)  # the learned H is an ordinary system
    assert np.all(np.isfinite(z))


class Stiffness(eqx.Module):
    """H = p²/2 + b·q²/2, b unknown."""

    b: jax.Array

    def __call__(self, q, p):
        return p[0] ** 2 / 2 + self.b * q[0] ** 2 / 2


@pytest.mark.long
def test_positions_alone_suffice_through_the_solver_and_the_hnn_refuses_them():
    """Only q observed (p NaN): the segments' unknown starting momenta are trained with b, and b = 2
    is recovered from the positions; the HNN, which needs every component, refuses in one line."""
    partial = [(t, np.column_stack([z[:, 0], np.full(t.size, np.nan)])) for t, z in _trajectories()]
    result = learn_hamiltonian(Stiffness(jnp.array(1.2)), partial, ThroughSolver(steps=300, rate=0.05))
    assert abs(float(result.model.b) - 2.0) < 0.01 and result.loss < 1e-7
    # no held-out state is observed whole: the held-out part is predicted from the last trained start
    assert result.held_out_loss is not None and result.trusted, result.notes
    with pytest.raises(ConfigError, match=r"trajectory 0 has components not observed \(NaN\)"):
        learn_hamiltonian(Stiffness(jnp.array(1.2)), partial, HNN())


@pytest.mark.long
def test_hnn_recovers_a_known_form_and_is_trusted():
    result = learn_hamiltonian(_guess(), _trajectories(), HNN(steps=400, rate=0.05), noise=0.0)
    assert abs(float(result.model.a) - 1.0) < 0.01 and abs(float(result.model.b) - 2.0) < 0.02
    assert result.trusted, result.notes
    assert result.curve[-1] < result.curve[0] / 100


def test_an_hnn_far_above_the_noise_is_not_trusted_and_no_noise_given_is_said():
    """Two Adam steps from a = 0.7, b = 1 cannot fit b = 2: the HNN's loss is far above what noise
    of 0.01 gives its central differences (2σ²/Δ²), so it is untrusted; without noise, a note says
    that the loss was not judged."""
    short = learn_hamiltonian(_guess(), _trajectories(noise=0.01), HNN(steps=2), noise=0.01)
    assert not short.trusted and "the noise's own" in short.notes[0]
    assert short.noise_loss == pytest.approx(2 * 0.01 ** 2 / 0.2 ** 2) and short.loss > 3 * short.noise_loss
    quiet = learn_hamiltonian(_guess(), _trajectories(), HNN(steps=2))
    assert any("no noise was given" in n for n in quiet.notes) and quiet.noise_loss is None


def test_a_held_out_part_from_other_dynamics_is_not_generalised_to():
    """The last fifth of every trajectory follows b = 8, the rest b = 2: the held-out loss is far
    above the training loss, and the result says it does not generalise."""
    mixed = []
    for (t, z), (_, other) in zip(_trajectories(), _trajectories(b=8.0)):
        cut = TIMES.size - TIMES.size // 5
        mixed.append((t, np.concatenate([z[:cut], other[cut:]])))
    result = learn_hamiltonian(_guess(), mixed, HNN(steps=200, rate=0.05))
    assert not result.trusted and any("does not generalise" in n for n in result.notes)


def test_ctrl_c_keeps_the_best_model_so_far():
    def interrupt(step, loss):
        if step > 8:
            raise KeyboardInterrupt

    result = learn_hamiltonian(_guess(), _trajectories(), HNN(steps=1000, rate=0.05), progress=interrupt)
    assert result.stopped.startswith("interrupted after") and result.steps < 1000
    assert not result.trusted and "stopped early" in result.notes[0]
    assert np.isfinite(float(result.model.a)) and result.loss <= result.curve[0]


class Exploding(eqx.Module):
    c: jax.Array

    def __call__(self, q, p):
        return p[0] ** 2 / 2 + jnp.exp(self.c * q[0] ** 2)


def test_a_model_that_blows_up_stops_the_training_and_says_so():
    result = learn_hamiltonian(Exploding(jnp.array(900.0)), _trajectories(), HNN(steps=20))
    assert result.stopped is not None and "not finite" in result.stopped and not result.trusted


class Quartic(eqx.Module):
    c: jax.Array

    def __call__(self, q, p):
        return p[0] ** 2 / 2 - self.c * q[0] ** 4


@pytest.mark.long
def test_a_solve_that_fails_inside_training_stops_it_with_the_solves_reason():
    """H = p²/2 − 50 q⁴ from q = 1 escapes to infinity within a segment: the traced solve spends
    its window budget, and the result carries that reason in one line."""
    result = learn_hamiltonian(Quartic(jnp.array(50.0)), _trajectories()[:1], ThroughSolver(steps=3, ahead=2))
    assert result.stopped.startswith("the solve failed at step 1: solve (traced core): the window budget")
    assert "\n" not in result.stopped and not result.trusted


class Affine(eqx.Module):
    w: jax.Array

    def __call__(self, q, p):
        return jnp.dot(self.w, jnp.concatenate([q, p]))


def _data_with(k, **change):
    t, z = TIMES.copy(), _trajectories()[0][1].copy()
    if "t_swap" in change:
        t[[4, 5]] = t[[5, 4]]
    if "inf" in change:
        z[3, 1] = np.inf
    return [(t, z)] if "shape" not in change else [(t, z[:, :1])]


@pytest.mark.parametrize("call, message", [
    (lambda: learn_hamiltonian(_guess(), _data_with(0, t_swap=1)), r"trajectory 0: times must increase strictly, but t\[5\]"),
    (lambda: learn_hamiltonian(_guess(), _data_with(0, inf=1)), "trajectory 0: times and states must be finite"),
    (lambda: learn_hamiltonian(_guess(), _data_with(0, shape=1)), r"states must have shape \(31, 2d\)"),
    (lambda: learn_hamiltonian(_guess(), []), "trajectories is empty"),
    (lambda: learn_hamiltonian(_guess(), "data.csv"), "trajectories must be a list"),
    (lambda: learn_hamiltonian(_guess(), _trajectories(), dof=2), "dof = 2 needs states of 4 components"),
    (lambda: learn_hamiltonian(_guess(), [(TIMES[:4], np.zeros((4, 2)))], ThroughSolver(ahead=5)),
     "no training segment: the longest trajectory has 4 observations"),
    (lambda: learn_hamiltonian(lambda q, p: p[0] ** 2, _trajectories()), "no floating-point arrays to train"),
    (lambda: learn_hamiltonian(Affine(jnp.ones(2)), _trajectories()), r"H_θ is affine in \(q, p\)"),
    (lambda: learn_hamiltonian(_guess(), _trajectories(), held_out=1.0), r"held_out must be a fraction in \[0, 1\)"),
    (lambda: learn_hamiltonian(_guess(), _trajectories(), noise=-1.0), "noise must be a finite number >= 0"),
    (lambda: learn_hamiltonian(_guess(), _trajectories(), method="hnn"), "method must be ThroughSolver"),
    (lambda: ThroughSolver(ahead=0), "ThroughSolver ahead must be an integer >= 1"),
    (lambda: HNN(rate=-1.0), "HNN rate must be a finite number > 0"),
], ids=["times-out-of-order", "inf", "shape", "empty", "a-path", "dof", "too-short", "no-weights", "affine",
        "held-out", "noise", "method", "ahead", "rate"])
@pytest.mark.long
def test_bad_input_is_refused_in_one_line_before_training(call, message):
    with pytest.raises(ConfigError, match=message) as err:
        call()
    assert "\n" not in str(err.value)


def test_a_fit_no_rule_could_judge_is_not_trusted():
    """No noise level and nothing held out: neither the noise floor nor the held-out check can run,
    so the learned H is not called trusted, and the note says what to give."""
    result = learn_hamiltonian(_guess(), _trajectories(), HNN(steps=50, rate=0.05), held_out=0.0)
    assert result.held_out_loss is None and not result.trusted
    assert any("no rule could judge" in note for note in result.notes)
    judged = learn_hamiltonian(_guess(), _trajectories(), HNN(steps=50, rate=0.05), held_out=0.0, noise=0.01)
    assert not any("no rule could judge" in note for note in judged.notes)


def _positions(trajectories):
    return [(t, np.column_stack([z[:, 0], np.full(t.size, np.nan)])) for t, z in trajectories]


def _mixed(b_after=8.0):
    """Orbits of b = 2 whose last fifth follows b = ``b_after``."""
    out = []
    for (t, z), (_, other) in zip(_trajectories(), _trajectories(b=b_after)):
        cut = TIMES.size - TIMES.size // 5
        out.append((t, np.concatenate([z[:cut], other[cut:]])))
    return out


@pytest.mark.long
def test_positions_only_are_still_checked_on_their_held_out_part():
    """p never observed: no held-out segment starts from a whole state, so the held-out part is
    predicted from each trajectory's last trained start; a last fifth from other dynamics shows."""
    result = learn_hamiltonian(Stiffness(jnp.array(1.2)), _positions(_mixed()), ThroughSolver(steps=200, rate=0.05))
    assert result.held_out_loss is not None and not result.trusted
    assert any("does not generalise" in n for n in result.notes)


def _coarse(spacing, noise=0.0):
    times = np.arange(0.0, 12.0 + 1e-9, spacing)
    truth = atlasnn.HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + q[0] ** 2, 1)
    rng = np.random.default_rng(1)
    return [(times, atlasnn.solve(truth, z, (0.0, 12.0))(times) + noise * rng.standard_normal((times.size, 2)))
            for z in ([1.0, 0.0], [0.0, 1.0], [0.5, 0.5])]


@pytest.mark.long
def test_an_hnn_on_differences_too_coarse_or_too_noisy_is_not_trusted():
    """Spring b = 2 observed every 0.5: central differences shrink the rates by sin(ωΔ)/(ωΔ), so the
    HNN's b is several per cent off while fitting its differences well; its flow misses the
    observations, which the result says (noise=0 given: exact data). Every 0.1 with σ = 0.3: the
    differences are mostly noise. Every 0.1 with σ = 0.01, b within 1 % — but the differences'
    O(Δ²) shrinkage is still in it, and over the data's span of 12 its flow drifts off them by more
    than 1 % of their size (which the span check says, and nothing else does)."""
    coarse = learn_hamiltonian(Stiffness(jnp.array(1.2)), _coarse(0.5), HNN(steps=300, rate=0.05), noise=0.0)
    assert abs(float(coarse.model.b) - 2.0) > 0.05 and not coarse.trusted
    assert any("too coarse" in n for n in coarse.notes)
    noisy = learn_hamiltonian(Stiffness(jnp.array(1.2)), _coarse(0.1, 0.3), HNN(steps=100, rate=0.05), noise=0.3)
    assert not noisy.trusted and any("regresses on noise" in n for n in noisy.notes)
    assert any("do not pin H down" in n for n in noisy.notes)
    dense = learn_hamiltonian(Stiffness(jnp.array(1.2)), _coarse(0.1, 0.01), HNN(steps=300, rate=0.05), noise=0.01)
    assert abs(float(dense.model.b) - 2.0) < 0.02 and not dense.trusted
    assert len(dense.notes) >= 1 and "H_θ's flow from starts fitted to them" in dense.notes[0], dense.notes
    assert 0.01 < dense.drift.drift < 0.05 and dense.expected_error(120.0) > 0.3


class Coupled(eqx.Module):
    """H = p²/2 + b·q²/2 + c·q·p: not separable."""

    b: jax.Array
    c: jax.Array

    def __call__(self, q, p):
        return p[0] ** 2 / 2 + self.b * q[0] ** 2 / 2 + self.c * q[0] * p[0]


@pytest.mark.long
def test_through_a_splitting_recovers_a_separable_form_and_refuses_a_coupled_one():
    """Fixed explicit steps (a batched scan) instead of the Gauss solver: b = 2 from exact orbits
    observed every 0.1, 4 Blanes–Moan steps over each 5-observation segment; a model coupling q
    and p, or a splitting without a step count, is refused in one line before training."""
    from atlasnn.solver import SplittingComposition

    method = ThroughSolver(steps=150, rate=0.05, solver=SplittingComposition(scheme="blanes_moan_rkn4", steps=4))
    result = learn_hamiltonian(Stiffness(jnp.array(1.2)), _trajectories(), method, noise=0.0)
    assert abs(float(result.model.b) - 2.0) < 2e-3 and result.held_out_loss is not None
    with pytest.raises(ConfigError, match=r"separable H_θ = T\(p\) \+ V\(q\), but ∂²H_θ/∂q∂p reaches"):
        learn_hamiltonian(Coupled(jnp.array(1.2), jnp.array(0.1)), _trajectories(), method)
    with pytest.raises(ConfigError, match=r"needs its steps=N"):
        ThroughSolver(solver=SplittingComposition(scheme="leapfrog"))


def test_a_splittings_observations_on_its_steps_are_read_from_the_march(monkeypatch):
    """With N steps over each segment of uniformly spaced observations, every observation is a step's
    end: the loss reads the marched states (no partial step), equal to evaluating the solution there;
    end-to-end segments (stride = ahead) predict each observation once."""
    from atlasnn.inverse import _learn
    from atlasnn.inverse._learn_data import check_trajectories
    from atlasnn.solver import SplittingComposition

    data = check_trajectories(_trajectories())
    method = ThroughSolver(ahead=5, stride=5, solver=SplittingComposition(scheme="leapfrog", steps=10))
    t0 = np.array([0.0, 2.0])
    times = t0[:, None] + np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    assert _learn._on_steps(method.solver, t0, times).tolist() == [[2, 4, 6, 8, 10]] * 2  # 10 steps of 0.05
    assert _learn._on_steps(SplittingComposition(scheme="leapfrog", steps=7), t0, times) is None
    model = Stiffness(jnp.array(1.7))
    with jax.enable_x64(True):
        direct = float(method.losses(data, 0.2, 1)[0](model, jnp.zeros(0)))
        monkeypatch.setattr(_learn, "_on_steps", lambda *args: None)
        evaluated = float(method.losses(data, 0.2, 1)[0](model, jnp.zeros(0)))
    assert direct == pytest.approx(evaluated, rel=1e-10) and direct > 0


@pytest.mark.long
def test_one_leapfrog_step_an_interval_learns_the_modified_h_and_says_so():
    """Spring b = 2 observed every 0.5 (exact data): one leapfrog step an interval reproduces the data
    with the leapfrog's modified stiffness, 2(1 − cos(√2·0.5))/0.5² ≈ 1.918, whose accurate flow
    misses the observations — untrusted, naming the modified Hamiltonian; eight steps an interval
    learn b = 2 within 0.2 % and are trusted."""
    from atlasnn.solver import SplittingComposition

    data = _coarse(0.5)
    modified = 2 * (1 - np.cos(np.sqrt(2.0) * 0.5)) / 0.25
    one = learn_hamiltonian(Stiffness(jnp.array(1.2)), data, ThroughSolver(
        steps=200, rate=0.05, solver=SplittingComposition(scheme="leapfrog", steps=5)), noise=0.0)
    assert abs(float(one.model.b) - modified) < 5e-3 and not one.trusted
    assert any("modified Hamiltonian of leapfrog" in note for note in one.notes), one.notes
    eight = learn_hamiltonian(Stiffness(jnp.array(1.2)), data, ThroughSolver(
        steps=200, rate=0.05, solver=SplittingComposition(scheme="leapfrog", steps=40)), noise=0.0)
    assert abs(float(eight.model.b) - 2.0) < 4e-3 and eight.trusted, eight.notes


@pytest.mark.long
def test_a_known_forms_standard_error_covers_its_error_and_flags_what_the_data_cannot_pin_down():
    """A model of few values gets standard errors from the residuals' Jacobian. Spring b = 2, q only
    with σ = 0.02 over [0, 12] in end-to-end segments: b within three standard errors of 2, trusted.
    Over [0, 1.2] in short overlapping segments (each fitting its own momentum) the error bar is wide
    and says so; stopped after a few steps, a Gauss–Newton step says the training fell short."""
    from atlasnn.solver import SplittingComposition

    def positions(span, seed=3):
        times = np.arange(0.0, span + 1e-9, 0.1)
        truth = atlasnn.HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + q[0] ** 2, 1)
        rng = np.random.default_rng(seed)
        return [(times, np.column_stack([atlasnn.solve(truth, z, (0.0, span))(times)[:, 0]
                                         + 0.02 * rng.standard_normal(times.size), np.full(times.size, np.nan)]))
                for z in ([1.0, 0.0], [0.0, 1.0])]

    def method(ahead, stride, steps=300):
        return ThroughSolver(steps=steps, rate=0.05, ahead=ahead, stride=stride,
                             solver=SplittingComposition(scheme="leapfrog", steps=4 * ahead))

    long = learn_hamiltonian(Stiffness(jnp.array(1.2)), positions(12.0), method(10, 10), noise=0.02)
    assert long.std is not None and abs(float(long.model.b) - 2.0) < 3 * long.std[0] < 0.2, (long.model.b, long.std)
    assert long.trusted, long.notes
    short = learn_hamiltonian(Stiffness(jnp.array(1.2)), positions(1.2), method(5, 1), noise=0.02)
    assert any("do not determine every parameter" in n for n in short.notes) and not short.trusted, short.notes
    early = learn_hamiltonian(Stiffness(jnp.array(1.2)), positions(12.0), method(10, 10, steps=40), noise=0.02)
    assert any("stopped short of the loss's minimum" in n for n in early.notes) and not early.trusted, early.notes


def test_the_span_check_reads_a_wrong_frequency_and_its_growth_over_time():
    """The span check (no training): spring b = 2 observed exactly over [0, 3]; H_θ with b = 2 does
    not drift, b = 2.01 drifts by a fraction of 1 % and its expected error ten spans on is within 2×
    of the error a solve from an exact start makes there, b = 2.1 drifts by more than 1 % (a reason
    not to trust it). With σ = 0.05 the drift of b = 2.01 is below what the noise lets the check see:
    the expected error is the noise's floor grown, not the small true one."""
    from atlasnn.inverse._learn_checks import drift_reasons, span_drift
    from atlasnn.inverse._learn_data import check_trajectories

    data = check_trajectories(_trajectories())
    size = float(np.sqrt(np.mean(np.concatenate([traj.z for traj in data]) ** 2)))
    assert span_drift(Stiffness(jnp.array(2.0)), 1, data, 0.0).drift < 1e-8
    near = span_drift(Stiffness(jnp.array(2.01)), 1, data, 0.0)
    truth = atlasnn.HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + q[0] ** 2, 1)
    t = np.linspace(0.0, 30.0, 301)
    miss = np.abs(atlasnn.solve(atlasnn.HamiltonianSystem(Stiffness(jnp.array(2.01)), 1), [1.0, 0.0], (0.0, 30.0))(t)
                  - atlasnn.solve(truth, [1.0, 0.0], (0.0, 30.0))(t)).max() / size
    assert 1e-3 < near.drift < 1e-2 and not drift_reasons(near, 0.0)
    assert 0.5 * miss < near.expected_error(30.0) < 2.0 * miss
    far = span_drift(Stiffness(jnp.array(2.1)), 1, data, 0.0)
    assert far.drift > 1e-2 and "beyond the noise: its predictions drift" in drift_reasons(far, 0.0)[0]
    noisy = span_drift(Stiffness(jnp.array(2.01)), 1, check_trajectories(_trajectories(noise=0.05)), 0.05)
    assert noisy.drift < noisy.floor and noisy.expected_error(30.0) > 3 * miss


def test_the_flow_check_reads_each_whole_state_s_next_observations():
    """The flow check (no training): oscillators of b = 2 observed exactly every 0.1, one state
    missing in each; H_θ with b = 2 misses nothing, b = 2.1 misses by the rms over every pair (a
    whole state, one of the next five whole ones) of the exact rotation's miss, in closed form."""
    from atlasnn.inverse._learn_checks import FLOW_AHEAD, flow_miss
    from atlasnn.inverse._learn_data import check_trajectories

    data = [(t, z.copy()) for t, z in _trajectories(b=2.0, starts=([1.0, 0.0], [0.3, -0.8], [0.0, 1.0]))]
    for k, (_, z) in enumerate(data):
        z[7 + 5 * k] = np.nan  # an observation lost: neither a start nor a target
    trajectories = check_trajectories(data)
    assert flow_miss(Stiffness(jnp.array(2.0)), 1, trajectories, 0.0) is None
    squares = []
    for t, z in data:
        for i in range(t.size):
            for j in range(i + 1, min(i + FLOW_AHEAD, t.size - 1) + 1):
                if np.all(np.isfinite(z[i])) and np.all(np.isfinite(z[j])):
                    w, tau = np.sqrt(2.1), t[j] - t[i]  # the rotation of H = p²/2 + 2.1 q²/2 over tau
                    q = z[i, 0] * np.cos(w * tau) + z[i, 1] / w * np.sin(w * tau)
                    p = -z[i, 0] * w * np.sin(w * tau) + z[i, 1] * np.cos(w * tau)
                    squares += [(q - z[j, 0]) ** 2, (p - z[j, 1]) ** 2]
    said = flow_miss(Stiffness(jnp.array(2.1)), 1, trajectories, 0.0)
    assert said is not None and f"by rms {np.sqrt(np.mean(squares)):.3g}," in said, (said, np.sqrt(np.mean(squares)))


def test_fitted_starts_are_unknowns_and_their_observed_values_targets():
    """fit_starts: every segment's whole start is trained with θ, from its observed values, which
    join the targets: at the observed starts the loss is the same predictions' over one more
    target each (exact weights: A/(A + 1) of it), and moving a start moves the loss."""
    from atlasnn.inverse._learn_data import check_trajectories
    from atlasnn.solver import SplittingComposition

    data = check_trajectories(_trajectories(noise=0.01))
    solver = SplittingComposition(scheme="leapfrog", steps=10)
    plain = ThroughSolver(ahead=5, stride=5, solver=solver)
    fitted = ThroughSolver(ahead=5, stride=5, fit_starts=True, solver=solver)
    model = Stiffness(jnp.array(2.0))
    with jax.enable_x64(True):
        loss, _, none = plain.losses(data, 0.2, 1)
        loss_fit, held, guess = fitted.losses(data, 0.2, 1)
        assert none.size == 0 and guess.size == 2 * 4 * 2  # 4 end-to-end segments a trajectory before its held-out part
        at_observed = float(loss_fit(model, guess))
        assert at_observed == pytest.approx(float(loss(model, none)) * 5 / 6, rel=1e-12)
        assert float(loss_fit(model, guess + 0.01)) != pytest.approx(at_observed, rel=1e-3) and held is not None
    with pytest.raises(ConfigError, match="fit_starts must be True or False"):
        ThroughSolver(fit_starts=1)


def test_the_noise_s_own_loss_is_what_the_true_h_reaches_from_observed_and_fitted_starts():
    """The allowance the trust rule compares a loss with (`noise_loss`) is what the true H reaches on
    noisy data (σ = 0.01): from the observed starts about 2σ², the target's noise and the start's
    carried forward; with every start fitted (least squares over them, θ held) about σ², for a
    fitted start carries no noise forward — half the allowance of the observed starts'."""
    from atlasnn.inverse._learn_data import check_trajectories
    from atlasnn.solver import SplittingComposition

    sigma, rng = 0.01, np.random.default_rng(1)
    data = check_trajectories(_trajectories(noise=sigma, starts=rng.uniform(-1.0, 1.0, (12, 2))))
    solver = SplittingComposition(scheme="leapfrog", steps=40)  # its error ~1e-5, far below σ
    model = Stiffness(jnp.array(2.0))
    for fit in (False, True):
        method = ThroughSolver(ahead=5, stride=5, fit_starts=fit, solver=solver)
        residual, _ = method.residuals(data, 0.2, 1)
        _, _, guess = method.losses(data, 0.2, 1)
        if fit:  # the residuals are affine in the starts (leapfrog on a linear field): one Gauss–Newton step
            jac = jax.jacfwd(lambda u: residual(model, u))(guess)
            guess = guess - jnp.linalg.lstsq(jac, residual(model, guess))[0]
        reached, allowed = float(jnp.sum(residual(model, guess) ** 2)), method.noise_loss(sigma, data)
        assert allowed == pytest.approx((1.0 if fit else 2.0) * sigma ** 2)
        assert allowed / 1.5 < reached < 1.25 * allowed, (fit, reached / sigma ** 2)


def test_a_trajectory_held_out_whole_is_never_trained_on_and_judges_the_fit():
    """held_out_trajectories=k: the last k trajectories are held out whole — every segment (or central
    difference) of theirs in the held-out part, none in training — and a value that would leave no
    trajectory to train on is refused in one line."""
    from atlasnn.inverse._learn_data import check_trajectories, hold_whole, rates, segments

    data = hold_whole(check_trajectories(_trajectories(starts=([1.0, 0.0], [0.0, 1.0], [0.5, 0.5]))), 1)
    assert [traj.held for traj in data] == [False, False, True]
    train, test = segments(data, 5, 0.2)
    held_starts = {tuple(z) for z in data[2].z[:-5]}
    assert not held_starts & {tuple(z) for z in train.starts} and held_starts <= {tuple(z) for z in test.starts}
    (states, _), (held_states, _) = rates(data, 0.2)
    assert not {tuple(z) for z in data[2].z} & {tuple(z) for z in states} and len(held_states) > 29
    for count in (3, -1, 1.5):
        with pytest.raises(ConfigError, match=r"held_out_trajectories must be an integer in \[0, 2\]"):
            learn_hamiltonian(_guess(), _trajectories(starts=([1.0, 0.0], [0.0, 1.0], [0.5, 0.5])), HNN(steps=1),
                              held_out_trajectories=count)


def test_a_step_that_biases_a_known_form_is_said_and_refining_it_moves_towards_the_truth():
    """Spring b = 2 observed exactly every 0.5, one leapfrog step an interval: near its least-squares
    minimum (b ≈ 1.918, the modified stiffness) the minimum through steps half as long lies closer to
    2 by more than the standard error — a reason not to trust it; eight steps an interval at b = 2
    move b by less than 0.1 %, and nothing is said."""
    from atlasnn.inverse._learn_data import check_trajectories
    from atlasnn.inverse._learn_errors import standard_errors
    from atlasnn.solver import SplittingComposition

    data = check_trajectories(_coarse(0.5))
    for steps, modified in ((5, 2 * (1 - np.cos(np.sqrt(2.0) * 0.5)) / 0.25), (40, 2.0)):
        method = ThroughSolver(solver=SplittingComposition(scheme="leapfrog", steps=steps))
        with jax.enable_x64(True):
            std, reasons = standard_errors(method.residuals(data, 0.2, 1), Stiffness(jnp.array(modified)),
                                           jnp.zeros(0), method.refined_residuals(data, 0.2, 1))
        biased = [r for r in reasons if r.startswith("the step biases θ")]
        if steps == 5:
            moved = float(biased[0].split("→ ")[1].split(",")[0])
            assert modified < moved < 2.0 and moved - modified > 2 * std[0], reasons
        else:
            assert not biased, reasons
    assert HNN().refined_residuals(data, 0.2, 1) is None
