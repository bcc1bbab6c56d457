"""The code blocks of the pages tests/test_docs.py assigns to shard 2 (its ``SHARDS``), run as that
file runs the others: a file of their own, so that pytest-xdist's ``--dist loadfile`` gives them to
another worker."""

from __future__ import annotations

import pytest
from test_docs import Block, block_params, check_block, epoch_cap, workspaces  # noqa: F401  (fixtures)


@pytest.mark.parametrize("block", block_params(2))
def test_block(block: Block, workspaces, epoch_cap, monkeypatch):  # noqa: F811  (the fixtures above)
    check_block(block, workspaces, monkeypatch)
