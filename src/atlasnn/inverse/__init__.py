"""Inverse problems: parameters of H (and initial-state components) identified from noisy,
partial observations by a network, two ways: one network trained on the data and Hamilton's
equations together (:func:`fit_joint`), or a bundle trained on the equations alone over the
unknowns' range and fitted afterwards (:func:`fit_with_bundle`). The classical baseline, least
squares shooting, is :func:`atlasnn.evaluation.fit_shooting`, and :func:`fit_multistart` runs it
from starts spread over the bounds; all return a :class:`~atlasnn.evaluation.FitResult`, which
:func:`judge_fit` marks untrusted where a rule says so."""

from atlasnn.inverse._bundle_fit import bundle_box_for, fit_with_bundle
from atlasnn.inverse._joint import JointConfig, fit_joint
from atlasnn.inverse._multistart import auto_starts, fit_multistart, judge_fit

__all__ = ["JointConfig", "fit_joint", "fit_with_bundle", "bundle_box_for", "fit_multistart", "judge_fit", "auto_starts"]
