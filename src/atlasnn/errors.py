"""The project's own error types.

Every error a user can cause (bad config, bad input, corrupt file) is raised as an
``AtlasError`` subclass whose message is one line naming the field and the value.
The CLI prints that line and exits with status 2.
"""


class AtlasError(Exception):
    """Base class for errors caused by user input; the message is one line."""


class ConfigError(AtlasError, ValueError):
    """A configuration value is missing, of the wrong type or out of range."""


class SystemError_(AtlasError, ValueError):
    """A Hamiltonian system is ill-defined or used where it cannot be (e.g. non-separable H)."""


class CheckpointError(AtlasError):
    """A checkpoint file is truncated, altered, foreign or incompatible."""


class ExpressionError(AtlasError, ValueError):
    """A Hamiltonian expression string is not allowed or does not parse."""


class ParametricSolveFailed(Exception):
    """An orbit of a parametric solve could not be integrated to its last time (a non-finite state,
    stage equations that did not converge on any window length tried). Not a user's error: the
    inverse fits catch it and try elsewhere, or say where the orbit failed."""
