"""A bundle or inverse-problem file given to a command that needs a trajectory experiment is
named for what it is, with the command that runs it; before, its first table was "an unknown key"."""

from __future__ import annotations

import pytest

from atlasnn.cli import main
from atlasnn.errors import ConfigError
from atlasnn.experiments.config import family_config_path, load_config


@pytest.mark.parametrize("name, what", [("pendulum-inverse", "an inverse-problem file"),
                                        ("oscillator-bundle", "a bundle file")])
@pytest.mark.parametrize("command", ["solve", "integrate"])
def test_a_family_file_is_named_for_what_it_is(name, what, command, capsys):
    path = family_config_path(name)
    assert main([command, str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and what in err and f"atlasnn family {path}" in err and "unknown key" not in err


def test_the_loader_says_it_too():
    with pytest.raises(ConfigError, match="is an inverse-problem file"):
        load_config(family_config_path("pendulum-inverse"))
