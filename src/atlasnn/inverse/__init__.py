"""Inverse problems: parameters of H (and initial-state components) identified from noisy,
partial observations, through one door, :func:`fit`, which takes a method object:

* :class:`Shooting` — least-squares shooting with forward sensitivities, the orbit by the compiled
  Gauss collocation (or DOP853) (:func:`fit_shooting`; multiple shooting with ``segments``), by
  default a multistart over the bounds (:func:`fit_multistart`);
* :class:`CollocationFit` — parameters, trajectory and its network weights solved together in
  float64 (:func:`fit_collocation`), then polished by shooting;
* :class:`Joint` — one network trained on the data and Hamilton's equations (:func:`fit_joint`);
* :class:`BundleFit` — a bundle trained over the unknowns' bounds, then fitted (:func:`fit_with_bundle`).

A Hamiltonian itself, a network H_θ or a form with unknown parts, is learned from trajectories by
its own door, :func:`learn_hamiltonian` (:class:`ThroughSolver`, :class:`HNN`), returning a
:class:`LearnedHamiltonian`.

All fits return a :class:`FitResult` (estimates, Gauss–Newton σ), which :func:`judge_fit` marks
untrusted where a rule says so. :func:`synthetic_observations` makes test data; the observations
themselves and the unknowns are :mod:`atlasnn.observations`' (the ground floor)."""

from atlasnn.inverse._base import AbstractFitMethod
from atlasnn.inverse._bundle_fit import bundle_box_for, fit_with_bundle
from atlasnn.inverse._collocation_fit import CollocationFit, fit_collocation
from atlasnn.inverse._fit_result import MISFIT_LIMIT, FitResult, distrust, flag_misfit, gauss_newton_covariance
from atlasnn.inverse._joint import JointConfig, fit_joint
from atlasnn.inverse._learn import HNN, AbstractLearnMethod, LearnedHamiltonian, ThroughSolver, learn_hamiltonian
from atlasnn.inverse._learn_checks import SpanDrift
from atlasnn.inverse._methods import FIT_METHODS, BundleFit, Joint, Shooting, fit, register_fit_method
from atlasnn.inverse._multistart import auto_starts, fit_multistart, judge_fit
from atlasnn.inverse._shooting import auto_segments, check_shooting_inputs, fit_shooting, predict_fit, shooting_misfit
from atlasnn.inverse._synthetic import synthetic_observations
from atlasnn.inverse._orbits import PARAMETRIC_SOLVERS, parametric_solver

__all__ = [
    "fit",
    "learn_hamiltonian",
    "ThroughSolver",
    "HNN",
    "AbstractLearnMethod",
    "LearnedHamiltonian",
    "SpanDrift",
    "AbstractFitMethod",
    "Shooting",
    "CollocationFit",
    "Joint",
    "BundleFit",
    "FIT_METHODS",
    "register_fit_method",
    "FitResult",
    "judge_fit",
    "distrust",
    "flag_misfit",
    "MISFIT_LIMIT",
    "gauss_newton_covariance",
    "fit_shooting",
    "fit_multistart",
    "fit_collocation",
    "JointConfig",
    "fit_joint",
    "fit_with_bundle",
    "bundle_box_for",
    "auto_starts",
    "check_shooting_inputs",
    "auto_segments",
    "shooting_misfit",
    "predict_fit",
    "synthetic_observations",
    "parametric_solver",
    "PARAMETRIC_SOLVERS",
]
