"""atlasnn.fileio: one atomic writer with the permissions of an ordinary file."""

from __future__ import annotations

import errno
import json
import math
import os
import stat

import numpy as np
import pytest

from atlasnn import fileio
from atlasnn.checkpoint import save_checkpoint
from atlasnn.errors import CheckpointError
from atlasnn.nn import make_model


@pytest.fixture
def umask():
    """Set the process umask for one test, and put the old one back."""
    old = os.umask(0o022)
    os.umask(old)
    yield lambda mask: os.umask(mask)
    os.umask(old)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask, expected", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_files_get_the_permissions_of_open(tmp_path, umask, ho, mask, expected):
    umask(mask)
    model = make_model(ho.z0, scaling="tanh", width=4, depth=1)
    save_checkpoint(tmp_path / "model.npz", model, ho, extra={"interval": [0.0, 1.0]})
    fileio.write_json(tmp_path / "results.json", {"a": 1})
    fileio.write_npz(tmp_path / "arrays.npz", {"t": np.arange(3.0)})
    with open(tmp_path / "plain.txt", "w") as f:  # what the tables get
        f.write("x")
    assert mode(tmp_path / "plain.txt") == expected
    for name in ("model.npz", "results.json", "arrays.npz"):
        assert mode(tmp_path / name) == expected, name
    assert fileio.current_umask() in (mask, None)


def test_an_existing_file_keeps_its_permissions(tmp_path, umask):
    umask(0o022)
    target = tmp_path / "meta.json"
    target.write_text("{}")
    os.chmod(target, 0o640)
    fileio.write_json(target, {"status": "complete"})
    assert mode(target) == 0o640 and json.loads(target.read_text()) == {"status": "complete"}


def test_json_conventions(tmp_path):
    data = {"f": np.float32(0.5), "i": np.int64(3), "b": np.bool_(True), "a": np.arange(3),
            "t": (1, 2), "nan": float("nan"), "inf": -math.inf}
    fileio.write_json(tmp_path / "x.json", data)
    text = (tmp_path / "x.json").read_text()
    assert text.startswith('{\n "f": 0.5')  # indent=1, as the runner's writer
    back = json.loads(text)
    assert back["i"] == 3 and back["b"] is True and back["a"] == [0, 1, 2] and back["t"] == [1, 2]
    assert math.isnan(back["nan"]) and back["inf"] == -math.inf
    with pytest.raises(TypeError, match="not JSON-serialisable: object"):
        fileio.write_json(tmp_path / "y.json", {"o": object()})
    assert not (tmp_path / "y.json").exists() and os.listdir(tmp_path) == ["x.json"]


def test_npz_round_trip(tmp_path):
    fileio.write_npz(tmp_path / "a.npz", {"t": np.linspace(0, 1, 5), "z": np.ones((5, 2), np.float32)})
    with np.load(tmp_path / "a.npz", allow_pickle=False) as z:
        assert z["t"][-1] == 1.0 and z["z"].dtype == np.float32


def test_a_failed_write_leaves_the_target_and_no_temporary_file(tmp_path):
    target = tmp_path / "results.json"
    target.write_text('{"old": true}')

    def full_disk(f):
        f.write(b"{partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(OSError) as info:
        fileio.write_atomic(target, full_disk)
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(target)
    assert info.value.strerror == "No space left on device"
    assert target.read_text() == '{"old": true}'
    assert os.listdir(tmp_path) == ["results.json"]

    with pytest.raises(KeyboardInterrupt):  # Ctrl-C in the middle: cleaned up too
        fileio.write_atomic(target, lambda f: (_ for _ in ()).throw(KeyboardInterrupt()))
    assert os.listdir(tmp_path) == ["results.json"]


def test_errors_name_the_target(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(NotADirectoryError) as info:
        fileio.write_json(afile / "results.json", {})
    assert info.value.filename == str(afile / "results.json")
    with pytest.raises(FileNotFoundError) as info:
        fileio.write_json(tmp_path / "missing" / "results.json", {})
    assert info.value.filename == str(tmp_path / "missing" / "results.json")


def test_checkpoint_write_errors_keep_their_message(tmp_path, ho, monkeypatch):
    model = make_model(ho.z0, scaling="tanh", width=4, depth=1)
    with pytest.raises(CheckpointError, match=r"^checkpoint .*afile/m\.npz: cannot write: Not a directory$"):
        (tmp_path / "afile").write_text("x")
        save_checkpoint(tmp_path / "afile" / "m.npz", model, ho)

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "savez", no_space)
    with pytest.raises(CheckpointError, match=r"m\.npz: cannot write: No space left on device$"):
        save_checkpoint(tmp_path / "m.npz", model, ho)
    assert sorted(os.listdir(tmp_path)) == ["afile"]
