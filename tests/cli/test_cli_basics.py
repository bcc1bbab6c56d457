"""The command line's own behaviour, apart from any command."""

from __future__ import annotations


def test_bare_atlasnn_is_a_usage_error(capsys):
    from atlasnn.cli import main

    assert main([]) == 2
    assert "name a command" in capsys.readouterr().err
