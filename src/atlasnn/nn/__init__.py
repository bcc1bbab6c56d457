"""The network side of ATLAS-NN: time scalings f(t; γ), the MLP N(t; θ) and the trial solution
ẑ(t) = z0 + f(t − t0; γ)·N(t; θ), and the model registry (a new scaling: one class, one entry)."""

from atlasnn.nn._bundle import BundleTrial, make_bundle_model
from atlasnn.nn._mlp import ACTIVATIONS, MLP
from atlasnn.nn._models import MODELS, SCALINGS, ModelKind, make_scaling, model_aliases, model_kind, register_model
from atlasnn.nn._scaling import ExpDecay, Linear, RationalExp, Tanh, TimeScaling, build_scaling, inverse_softplus, softplus
from atlasnn.nn._sincos import SINCOS_FAST_LIMIT, sin, sin_cos
from atlasnn.nn._trial import TrialSolution, make_model

__all__ = [
    "TimeScaling",
    "ExpDecay",
    "Tanh",
    "RationalExp",
    "Linear",
    "SCALINGS",
    "build_scaling",
    "softplus",
    "inverse_softplus",
    "ModelKind",
    "MODELS",
    "register_model",
    "model_kind",
    "model_aliases",
    "make_scaling",
    "MLP",
    "ACTIVATIONS",
    "sin_cos",
    "sin",
    "SINCOS_FAST_LIMIT",
    "TrialSolution",
    "make_model",
    "BundleTrial",
    "make_bundle_model",
]
