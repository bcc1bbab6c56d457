"""File-system errors at the command line: one line naming the path and the cause, exit status 2
before a run starts and 1 when it fails mid-run, never a traceback, finished work kept."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import subprocess

import pytest

from atlasnn.cli import main

from support import TINY  # noqa: F401


@pytest.fixture
def config(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY, encoding="utf-8")
    return path


def run_cli(argv, capsys):
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def one_line_error(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("atlasnn: error: ") and "Traceback" not in err
    return lines[0]


def test_out_below_a_regular_file(tmp_path, config, capsys):
    afile = tmp_path / "afile"
    afile.write_text("not a directory")
    status, out, err = run_cli(["run", config, "--out", afile / "run", "--no-progress"], capsys)
    assert status == 2
    assert one_line_error(err) == f"atlasnn: error: --out {afile / 'run'}: {afile} is not a directory"
    assert out == "" and afile.read_text() == "not a directory"  # refused before any work


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores file permissions")
def test_out_in_an_unwritable_directory(tmp_path, config, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        status, out, err = run_cli(["run", config, "--out", locked / "run", "--no-progress"], capsys)
    finally:
        locked.chmod(0o700)
    assert status == 2
    line = one_line_error(err)
    assert line == (f"atlasnn: error: --out {locked / 'run'}: cannot write in {locked} (where --out "
                    f"{locked / 'run'} would be created): Permission denied")
    assert os.listdir(locked) == []


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("setpriv") is None,
                    reason="as root, the same check runs the CLI as the user nobody (needs setpriv)")
def test_out_in_an_unwritable_directory_as_nobody():
    """Root ignores permissions, so run the command as nobody (uid 65534) in a directory that
    nobody may enter but not write into."""
    import sys
    import tempfile

    base = tempfile.mkdtemp(prefix="atlasnn-perm-")
    try:
        os.chmod(base, 0o755)
        locked = os.path.join(base, "locked")
        os.mkdir(locked, 0o555)
        config = os.path.join(base, "tiny.toml")
        with open(config, "w") as f:
            f.write(TINY)
        os.chmod(config, 0o644)
        as_nobody = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-c"]
        probe = subprocess.run(as_nobody + ["import atlasnn.cli._main"], capture_output=True, text=True, cwd=base)
        if probe.returncode != 0:
            pytest.skip(f"nobody cannot import atlasnn here: {probe.stderr.strip()[-200:]}")
        code = "import sys; from atlasnn.cli import main; sys.exit(main(sys.argv[1:]))"
        done = subprocess.run(as_nobody + [code, "run", config, "--out", os.path.join(locked, "run"), "--no-progress"],
                              capture_output=True, text=True, cwd=base, timeout=120)
        assert done.returncode == 2, done.stderr
        target = os.path.join(locked, "run")
        assert done.stderr == (f"atlasnn: error: --out {target}: cannot write in {locked} (where --out {target} "
                               "would be created): Permission denied\n")
        assert os.listdir(locked) == []
    finally:
        shutil.rmtree(base)


@contextlib.contextmanager
def tmpfs(path, options):
    """A real tmpfs mounted at ``path`` (needs root and mount rights; the test is skipped
    otherwise)."""
    path.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a file system needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "atlasnn-test", str(path)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=False)


def test_out_on_a_read_only_file_system(tmp_path, config, capsys):
    with tmpfs(tmp_path / "ro", "ro,size=1m") as ro:
        status, out, err = run_cli(["run", config, "--out", ro / "run", "--no-progress"], capsys)
        assert status == 2
        line = one_line_error(err)
        assert str(ro) in line and "Read-only file system" in line
        assert os.listdir(ro) == []


@pytest.mark.long
def test_a_full_disk_mid_run_for_real(tmp_path, config, capsys):
    # 40 KiB hold the config, meta.json and the first model's files, not the second model
    with tmpfs(tmp_path / "small", "size=40k") as small:
        run = small / "run"
        status, out, err = run_cli(["run", config, "--out", run, "--no-progress"], capsys)
        assert status == 1
        line = one_line_error(err)
        assert "No space left on device" in line and str(run) in line
        assert (run / "tasks" / "short_hnn_seed0.json").is_file()  # the finished training is kept
        assert (run / "models" / "hnn_seed0.npz").is_file()


def test_a_full_disk_mid_run_simulated(tmp_path, config, capsys, monkeypatch):
    import atlasnn.checkpoint._format as ck  # where _write_atomic looks up write_atomic

    real = ck.write_atomic

    def second_model_fails(path, write):
        if "atlas_exp" in os.fspath(path):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), os.fspath(path))
        return real(path, write)

    monkeypatch.setattr(ck, "write_atomic", second_model_fails)
    run = tmp_path / "run"
    status, out, err = run_cli(["run", config, "--out", run, "--no-progress"], capsys)
    assert status == 1
    assert one_line_error(err) == (f"atlasnn: error: checkpoint {run / 'models' / 'atlas_exp_seed0.npz'}: "
                                   "cannot write: No space left on device")
    assert (run / "models" / "hnn_seed0.npz").is_file() and (run / "tasks" / "short_hnn_seed0.json").is_file()
    assert not any(p.name.endswith(".tmp") for p in (run / "models").iterdir())


def test_a_full_disk_before_the_run_starts(tmp_path, config, capsys, monkeypatch):
    import atlasnn.experiments._runner as runner

    def no_space(path, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # no file name: the CLI adds the run

    monkeypatch.setattr(runner, "write_json", no_space)
    run = tmp_path / "run"
    status, out, err = run_cli(["run", config, "--out", run, "--no-progress"], capsys)
    assert status == 2  # nothing had been trained: meta.json was never written
    assert one_line_error(err) == f"atlasnn: error: No space left on device (writing in {run})"


def test_an_os_error_names_both_paths_of_a_rename(tmp_path, config, capsys, monkeypatch):
    import atlasnn.experiments._runner as runner

    def cannot_rename(path, data):
        raise OSError(errno.EXDEV, os.strerror(errno.EXDEV), "/a/tmp", None, "/b/results.json")

    monkeypatch.setattr(runner, "write_json", cannot_rename)
    status, out, err = run_cli(["run", config, "--out", tmp_path / "run", "--no-progress"], capsys)
    assert status == 2
    assert one_line_error(err) == "atlasnn: error: cannot move /a/tmp to /b/results.json: Invalid cross-device link"


def test_report_of_an_unreadable_directory(tmp_path, capsys):
    status, out, err = run_cli(["report", tmp_path / "nowhere"], capsys)
    assert status == 2
    line = one_line_error(err)
    assert "nowhere" in line
