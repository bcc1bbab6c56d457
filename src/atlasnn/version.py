"""The package version (one home: the top-level face and the checkpoint format read it)."""

__version__ = "0.1.0"
