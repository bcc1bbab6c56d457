"""Inverse problems: parameters of H (and initial-state components) identified from noisy,
partial observations by a network, two ways: one network trained on the data and Hamilton's
equations together (:func:`fit_joint`), or a bundle trained on the equations alone over the
unknowns' range and fitted afterwards (:func:`fit_with_bundle`). The classical baseline, least
squares shooting, is :func:`atlasnn.evaluation.fit_shooting`; all three return a
:class:`~atlasnn.evaluation.FitResult`."""

from atlasnn.inverse._bundle_fit import bundle_box_for, fit_with_bundle
from atlasnn.inverse._joint import JointConfig, fit_joint

__all__ = ["JointConfig", "fit_joint", "fit_with_bundle", "bundle_box_for"]
