"""The run directory: what a run writes, how it is written, and how a resumed run reads it back.

    config.toml      the config file as given          config.json   the resolved config
    meta.json        versions, seeds, plan, status     results.json  per-training metrics and facts
    arrays.npz       evaluation grid, reference, SE and model trajectories (for figures)
    models/          one checkpoint per trained model (with its loss and γ histories)
    tables.*, figures/   written by :mod:`atlasnn.report._render`
    tasks/           one record per finished training (JSON + trajectories as .npz)
    state/           training states of unfinished trainings (removed when the run completes)
    .lock            held (an OS file lock) by the one process that writes the run

Every file is written atomically (temporary file beside it, fsync, rename): a crash never leaves
a half-written file under a real name. A training's record in ``tasks/`` is its "finished"
marker; it names the run (``run_id``) and the SHA-256 of its trajectories, so a resumed run only
trusts records of its own. ``meta.json`` has a ``status``: ``running``, ``interrupted``,
``failed`` or ``complete``.
"""

from __future__ import annotations

import errno
import hashlib
import json
import math
import os
import platform
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from atlasnn.errors import ConfigError
from atlasnn.experiments.config import parse_config
from atlasnn.fileio import parse_toml, write_json, write_npz

TASK_DIR = "tasks"
STATE_DIR = "state"
LOCK_FILE = ".lock"
CHECKPOINT_SECONDS = 60.0  # default interval of the periodic state saves (ATLASNN_CHECKPOINT_SECONDS)


def one_line(text: Any) -> str:
    return " ".join(str(text).split())


def checkpoint_seconds() -> float:
    """Seconds between periodic state saves: ``ATLASNN_CHECKPOINT_SECONDS`` (default 60; 0 saves
    after every chunk of epochs)."""
    text = os.environ.get("ATLASNN_CHECKPOINT_SECONDS")
    if text is None or not text.strip():
        return CHECKPOINT_SECONDS
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not math.isfinite(value) or value < 0:
        raise ConfigError(f"ATLASNN_CHECKPOINT_SECONDS = {text!r}: expected a number of seconds >= 0")
    return value


def versions() -> dict[str, str]:
    """Versions of atlasnn and the libraries a result depends on."""
    import equinox
    import jax
    import jaxlib
    import optax
    import scipy

    from atlasnn.precision import matmul_precision
    from atlasnn.training import training_compiler_options
    from atlasnn.version import __version__

    return {
        "atlasnn": __version__, "jax": jax.__version__, "jaxlib": jaxlib.__version__,
        "equinox": equinox.__version__, "optax": optax.__version__, "numpy": np.__version__,
        "scipy": scipy.__version__, "python": platform.python_version(), "platform": platform.platform(),
        "backend": jax.default_backend(), "device": jax.devices()[0].device_kind,
        "matmul_precision": matmul_precision(), "cpu": cpu_model(), "cpu_count": str(os.cpu_count()),
        "training_xla_options": str(training_compiler_options() or "XLA's defaults"),
    }


def cpu_model() -> str:
    """The CPU's model name (what XLA's and YNNPACK's kernels are chosen for), or the machine type."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


# ------------------------------------------------------------------------- the lock
class RunLock:
    """An exclusive OS lock (``flock``) on ``DIR/.lock``: one writer per run directory.

    The OS releases it when the process exits, also on a crash or a kill, so a stale lock file
    never blocks a later run. Worker processes of the same run write into the directory under
    the parent's lock. (On a network file system ``flock`` may not exclude writers on other
    machines; run one coordinator per directory there.)
    """

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir) / LOCK_FILE
        self._fd: int | None = None

    def acquire(self) -> "RunLock":
        import fcntl

        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                holder = self._holder()
                raise ConfigError(f"run directory {self.path.parent} is in use by another atlasnn run"
                                  f"{holder}; wait for it to finish or choose another --out") from None
            raise
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._fd = fd
        return self

    def _holder(self) -> str:
        try:
            pid = self.path.read_text().strip()
        except OSError:
            return ""
        return f" (process {pid})" if pid.isdigit() else ""

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor releases the flock
            self._fd = None

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc) -> bool:
        self.release()
        return False


# -------------------------------------------------------------------- run directory
def _entries(out: Path) -> list[Path]:
    return [p for p in out.iterdir() if p.name != LOCK_FILE]


def check_run_dir(out: Path, overwrite: bool) -> None:
    """Refuse an existing non-empty ``out`` unless ``overwrite`` (creates nothing)."""
    out = Path(out)
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise ConfigError(f"output path exists and is not a directory: {out}")
        if _entries(out) and not overwrite:
            raise ConfigError(
                f"output directory {out} is not empty; pass --overwrite to reuse it, --resume {out} "
                "to continue an interrupted run in it, or choose another --out"
            )
    else:
        parent = next((p for p in out.parents if p.exists()), None)
        if parent is not None and not parent.is_dir():
            raise ConfigError(f"cannot create output directory {out}: {parent} is not a directory")


def open_run_dir(out: Path, overwrite: bool) -> RunLock:
    """Create ``out`` and take its lock (checking again under the lock: another run may have
    started between the first check and now)."""
    check_run_dir(out, overwrite)
    Path(out).mkdir(parents=True, exist_ok=True)
    lock = RunLock(out).acquire()
    try:
        check_run_dir(out, overwrite)
    except BaseException:
        lock.release()
        raise
    return lock


def read_run_meta(out: str | Path) -> dict[str, Any]:
    """``meta.json`` of a run directory that can be resumed (else a one-line ConfigError)."""
    out = Path(out)
    if not out.is_dir():
        raise ConfigError(f"--resume {out}: no such run directory")
    try:
        meta = json.loads((out / "meta.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"--resume {out}: not an atlasnn run directory (no meta.json)") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"--resume {out}: meta.json is not readable ({one_line(exc)})") from None
    if not isinstance(meta, dict):
        raise ConfigError(f"--resume {out}: meta.json is not a JSON object")
    status = meta.get("status")
    if status == "complete" or (status is None and (out / "results.json").exists()):
        raise ConfigError(f"--resume {out}: the run is already complete (`atlasnn report {out}` re-renders "
                          "it; --overwrite runs it again)")
    if not isinstance(meta.get("run_id"), str) or not isinstance(meta.get("seeds"), list):
        raise ConfigError(f"--resume {out}: meta.json has no run_id or seeds (not written by a resumable "
                          "atlasnn run); start it again with --overwrite")
    return meta


def load_run_config(out: str | Path):
    """The config and meta of a resumable run directory: ``config.toml`` as given, parsed with the
    run's ``--quick`` flag (or the recorded config when there is no ``config.toml``)."""
    out = Path(out)
    meta = read_run_meta(out)
    quick = bool(meta.get("quick"))
    source = meta.get("config_source") or f"{meta.get('experiment', 'config')}.toml"
    toml = out / "config.toml"
    try:
        if toml.is_file():
            data = parse_toml(toml.read_text(encoding="utf-8"), str(toml))
        else:
            data = json.loads((out / "config.json").read_text(encoding="utf-8"))["as_given"]
            quick = False  # the recorded config is the merged one
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"--resume {out}: cannot read the run's config ({one_line(exc)})") from None
    return parse_config(data, quick=quick, source=str(source), profile=meta.get("profile")), meta


# ------------------------------------------------------------- records and states
class Training(Protocol):
    """What the store needs of one training (an :class:`~atlasnn.experiments._tasks.Task` of one seed)."""

    role: str
    model: str

    @property
    def seed(self) -> int: ...

    @property
    def state_names(self) -> tuple[str, ...]: ...


def task_stem(task: Training) -> str:
    """The file name (without suffix) of a finished training's record in ``tasks/``."""
    return f"{task.role}_{task.model}_seed{task.seed}"


def run_state(run_dir: Path) -> str:
    """``complete`` (results written), ``resumable`` (a run was started there) or ``new``."""
    try:
        meta = json.loads((Path(run_dir) / "meta.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return "new"
    if not isinstance(meta, dict):
        return "new"
    if meta.get("status") == "complete" and (Path(run_dir) / "results.json").is_file():
        return "complete"
    return "resumable" if isinstance(meta.get("run_id"), str) else "new"


def state_path(run_dir: Path, column: str, seed: int) -> Path:
    """Where the training state of ``column`` (seed ``seed``) is kept while it is unfinished."""
    return Path(run_dir) / STATE_DIR / f"{column}_seed{seed}.npz"


def source_state_path(run_dir: Path, model: str, seed: int) -> Path:
    """The final state of a finished transfer source (its Adam moments start the target);
    a JSON beside it (same stem) holds the source's record."""
    return state_path(run_dir, f"{model}_source", seed)


def state_files(run_dir: Path, training: Training) -> list[Path]:
    """Every state file one training may leave behind: a state per name of its ``state_names``
    (its column's; a transfer's source too), each with the JSON that may sit beside it."""
    files = []
    for name in training.state_names:
        path = state_path(run_dir, name, training.seed)
        files += [path, path.with_suffix(".json")]
    return files


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_record(run_dir: Path, training: Training, run_id: str | None, output: dict) -> None:
    """Keep a finished training: its trajectories (.npz), then its record (.json, the marker)."""
    tdir = Path(run_dir) / TASK_DIR
    tdir.mkdir(exist_ok=True)
    stem = task_stem(training)
    write_npz(tdir / f"{stem}.npz", output["arrays"])
    write_json(tdir / f"{stem}.json", {
        "run_id": run_id, "task": {"role": training.role, "model": training.model, "seed": training.seed},
        "records": output["records"], "notes": output.get("notes", []),
        "arrays": f"{stem}.npz", "arrays_sha256": _sha256(tdir / f"{stem}.npz"),
    })


def load_record(run_dir: Path, training: Training, run_id: str) -> dict | None:
    """The output of a training finished earlier in this run (same run_id, intact files), or None."""
    tdir = Path(run_dir) / TASK_DIR
    path = tdir / f"{task_stem(training)}.json"
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict) or data.get("run_id") != run_id:
            return None
        npz = tdir / data["arrays"]
        if npz.parent != tdir or _sha256(npz) != data["arrays_sha256"]:
            return None
        with np.load(npz, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        records = data["records"]
        if not all((Path(run_dir) / r["checkpoint"]).is_file() for r in records):
            return None
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return {"records": records, "arrays": arrays, "notes": list(data.get("notes") or [])}


def forget_trainings(run_dir: Path, trainings: list[Training]) -> None:
    """Remove this tool's own records and states of these trainings (``--overwrite``)."""
    for t in trainings:
        stem = Path(run_dir) / TASK_DIR / task_stem(t)
        for path in [stem.with_suffix(".json"), stem.with_suffix(".npz"), *state_files(run_dir, t)]:
            path.unlink(missing_ok=True)


def clear_states(run_dir: Path, trainings: list[Training]) -> None:
    """After a complete run: the states are no longer needed (foreign files are left alone)."""
    for t in trainings:
        for path in state_files(run_dir, t):
            path.unlink(missing_ok=True)
    try:
        (Path(run_dir) / STATE_DIR).rmdir()
    except OSError:  # not empty (files that are not ours) or absent
        pass
