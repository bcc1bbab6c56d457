"""The command line: `atlasnn ...`."""

from atlasnn.cli._main import main

__all__ = ["main"]
