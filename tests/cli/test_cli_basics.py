"""The command line's own behaviour, apart from any command."""

from __future__ import annotations


def test_bare_atlasnn_is_a_usage_error(capsys):
    from atlasnn.cli import main

    assert main([]) == 2
    assert "name a command" in capsys.readouterr().err


def test_solve_help_quotes_the_tolerances_check_uses(capsys):
    """`atlasnn solve --help` said DOP853 at 1e-13 while --check ran it at 2.5e-14."""
    import pytest

    from atlasnn.cli import main
    from atlasnn.cli._solve_commands import CHECK_TOLERANCES

    with pytest.raises(SystemExit):
        main(["solve", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert CHECK_TOLERANCES["rtol"] == 2.5e-14
    assert "also compare with DOP853 at rtol 2.5e-14, atol 1e-14 (the true error)" in text
