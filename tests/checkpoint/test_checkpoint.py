"""Tests of checkpoint files: exact round trips, integrity checks, refusal of foreign or
pickled content, atomic writes, and an exactly resumable interrupted training run."""

from __future__ import annotations

import hashlib
import json
import os
import zipfile

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import atlasnn
from atlasnn.checkpoint import _single as ckpt
from atlasnn.checkpoint import load_checkpoint, load_state, save_checkpoint, save_state
from atlasnn.errors import AtlasError, CheckpointError
from atlasnn.nn import make_model
from atlasnn.solutions import Solution
from atlasnn.systems import HamiltonianSystem, harmonic_oscillator, henon_heiles, nonlinear_oscillator
from atlasnn.training import TrainConfig, train

T_EVAL = np.linspace(0.0, 3.0, 17)
GAMMAS = {"exp_decay": None, "tanh": {"m": 0.8}, "rational_exp": {"alpha": 0.7, "beta": 1.3}}

# The resumable run: 600 epochs in chunks of 300, jitter on so the epoch keys matter.
CFG = TrainConfig(
    epochs=600, chunk=300, n_points=20, lr=5e-3, betas=(0.9, 0.99), sigma=0.5, seed=1, progress=False
)
T_END = 2.0


def _small_model(scaling: str = "rational_exp", *, seed: int = 3, t0: float = 0.0, z0=(1.0, 0.0)):
    return make_model(z0, scaling=scaling, width=8, depth=2, gamma=GAMMAS[scaling], seed=seed, t0=t0)


def _leaves_equal(a, b) -> bool:
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    if jax.tree_util.tree_structure(a) != jax.tree_util.tree_structure(b) or len(la) != len(lb):
        return False
    return all(
        np.asarray(x).dtype == np.asarray(y).dtype and np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
        for x, y in zip(la, lb)
    )


def _load_error(path, **kwargs) -> str:
    """Load, expect a CheckpointError, check it is one line naming the file; return its text."""
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg
    assert isinstance(info.value, AtlasError)
    return msg


def _read_npz(path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _write_npz(path, arrays) -> None:
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _meta_bytes(meta) -> np.ndarray:
    return np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)


# ------------------------------------------------------------------ round trips
@pytest.mark.long
@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
@pytest.mark.parametrize("scaling", ["exp_decay", "tanh", "rational_exp"])
def test_round_trip_predicts_bit_identically(tmp_path, scaling, x64):
    system = harmonic_oscillator()
    path = tmp_path / "model.npz"
    with jax.enable_x64(x64):
        model = _small_model(scaling, t0=0.5)
        digest = save_checkpoint(path, model, system, extra={"interval": [0.5, 3.0]})
        ck = load_checkpoint(path)
        before = Solution(model, system)
        after = ck.solution()
        z_before, z_after = before(T_EVAL), after(T_EVAL)
        dz_before, dz_after = before.derivative(T_EVAL), after.derivative(T_EVAL)
    dtype = np.float64 if x64 else np.float32
    assert z_before.dtype == z_after.dtype == dtype
    assert np.array_equal(z_before, z_after)
    assert np.array_equal(dz_before, dz_after)
    assert _leaves_equal(model, ck.model)
    assert ck.model.scaling.name == model.scaling.name and ck.model.t0 == 0.5
    assert ck.meta["dtype"] == str(np.dtype(dtype))
    assert ck.content_sha256 == digest and len(digest) == 64
    # the built-in system came back from its spec
    assert ck.system.name == system.name and ck.system.spec == system.spec
    assert after.interval == (0.5, 3.0)
    assert sorted(os.listdir(tmp_path)) == ["model.npz"]  # no temporary file left behind


def test_float32_checkpoint_stays_float32_under_x64(tmp_path):
    system = harmonic_oscillator()
    model = _small_model("tanh")
    save_checkpoint(tmp_path / "m.npz", model, system)
    with jax.enable_x64(True):
        ck = load_checkpoint(tmp_path / "m.npz")
    assert _leaves_equal(model, ck.model)
    assert np.array_equal(Solution(model, system)(T_EVAL), ck.solution()(T_EVAL))


def test_non_finite_values_are_stored_as_is(tmp_path):
    system = harmonic_oscillator()
    model = _small_model("rational_exp")
    model = eqx.tree_at(lambda m: m.net.weights[1], model, model.net.weights[1].at[2, 3].set(jnp.nan))
    model = eqx.tree_at(lambda m: m.scaling.raw_alpha, model, jnp.asarray(jnp.inf, jnp.float32))
    save_checkpoint(tmp_path / "m.npz", model, system)
    ck = load_checkpoint(tmp_path / "m.npz")
    assert _leaves_equal(model, ck.model)
    assert np.isnan(np.asarray(ck.model.net.weights[1])[2, 3])
    assert ck.meta["gamma"]["alpha"] is None  # the meta is strict JSON; the array keeps inf
    assert ck.meta["gamma"]["beta"] == pytest.approx(1.3, rel=1e-6)


def test_expression_system_is_rebuilt_from_its_spec(tmp_path):
    from atlasnn.systems import expression_system

    system = expression_system("p**2/2 + q**2/2 + lam*q**4/4", ["q"], ["p"], params={"lam": 0.5}, name="quartic")
    model = _small_model("tanh")
    save_checkpoint(tmp_path / "m.npz", model, system)
    ck = load_checkpoint(tmp_path / "m.npz")
    assert ck.system.spec == system.spec
    z = np.array([[0.3, -0.2], [1.0, 0.5]])
    assert np.allclose(np.asarray(ck.system.energy(z)), np.asarray(system.energy(z)))


def test_python_function_system_must_be_passed(tmp_path):
    system = HamiltonianSystem(lambda q, p: p[0] ** 2 / 2 + q[0] ** 2 / 2 + 0.1 * q[0] ** 4, 1, name="mine")
    model = _small_model("tanh")
    path = tmp_path / "m.npz"
    save_checkpoint(path, model, system)
    msg = _load_error(path)
    assert "pass system" in msg and "'mine'" in msg
    ck = load_checkpoint(path, system=system)
    assert ck.system is system
    assert np.array_equal(ck.solution()(T_EVAL), Solution(model, system)(T_EVAL))
    assert "state dimension" in _load_error(path, system=henon_heiles())


def test_save_refuses_mismatched_system_and_unjsonable_extra(tmp_path):
    model = _small_model("tanh")
    with pytest.raises(CheckpointError, match="state dimension"):
        save_checkpoint(tmp_path / "a.npz", model, henon_heiles())
    with pytest.raises(CheckpointError, match="JSON"):
        save_checkpoint(tmp_path / "b.npz", model, harmonic_oscillator(), extra={"f": object()})
    assert os.listdir(tmp_path) == []


# ------------------------------------------------------------- a training run
def _interrupt_after_first_chunk(state):
    raise KeyboardInterrupt


@pytest.fixture(scope="module")
def runs():
    """(system, model, the full 600-epoch run, the same run interrupted after 300 epochs)."""
    system = nonlinear_oscillator()
    model = make_model(system.z0, scaling="rational_exp", width=8, depth=2, seed=2)
    full = train(model, system, T_END, CFG)
    half = train(model, system, T_END, CFG, on_chunk=_interrupt_after_first_chunk)
    assert full.stop_reason == "budget" and len(full.history) == 600
    assert half.stop_reason == "interrupted" and half.state.epoch == 300 and len(half.history) == 300
    return system, model, full, half


def test_history_and_meta_round_trip(tmp_path, runs):
    system, _, full, _ = runs
    path = tmp_path / "trained.npz"
    extra = {"model": "atlas_exp", "seed": 2, "interval": [0.0, T_END], "stop_reason": full.stop_reason}
    digest = save_checkpoint(path, full.model, system, history=full.history, train_config=CFG, extra=extra)
    ck = load_checkpoint(path)

    h = ck.history
    assert h is not None and len(h) == 600 and h.gamma_names == ("alpha", "beta")
    for name in ("loss", "residual", "energy", "gamma"):
        stored, orig = getattr(h, name), getattr(full.history, name)
        assert stored.dtype == orig.dtype and np.array_equal(stored, orig)

    m = ck.meta
    assert m["format"] == "atlasnn-checkpoint" and m["format_version"] == 1
    assert m["atlasnn_version"] == atlasnn.__version__ and m["jax_version"] == jax.__version__
    assert m["architecture"] == full.model.architecture()
    assert m["gamma"] == {k: float(v) for k, v in full.model.scaling.gamma().items()}
    assert m["z0"] == np.asarray(full.model.z0, np.float64).tolist() and m["t0"] == 0.0 and m["dtype"] == "float32"
    assert m["system"] == json.loads(json.dumps(system.describe()))
    assert m["train_config"]["betas"] == [0.9, 0.99] and m["train_config"]["epochs"] == 600
    assert ck.train_config() == CFG
    assert m["extra"] == extra and ck.interval == (0.0, T_END)
    leaves = jax.tree_util.tree_leaves(full.model)
    assert m["leaves"]["count"] == len(leaves)
    assert m["leaves"]["shapes"] == [list(x.shape) for x in leaves]
    assert m["content_sha256"] == digest
    assert _leaves_equal(ck.model, full.model)

    # the file layout and the hash, recomputed here from the documented recipe
    arrays = _read_npz(path)
    assert {"param_000", "history_loss", "history_residual", "history_energy", "history_gamma"} <= set(arrays)
    raw = arrays.pop("meta")
    assert raw.dtype == np.uint8 and raw.ndim == 1
    meta = json.loads(raw.tobytes().decode("utf-8"))
    stored = meta.pop("content_sha256")
    sha = hashlib.sha256(json.dumps(meta, sort_keys=True, separators=(",", ":")).encode("utf-8"))
    for name in sorted(arrays):
        a = arrays[name]
        header = json.dumps([name, a.dtype.str, list(a.shape)], separators=(",", ":")).encode("utf-8")
        data = a.tobytes()
        sha.update(len(header).to_bytes(8, "little") + header + len(data).to_bytes(8, "little") + data)
    assert sha.hexdigest() == stored == digest


def test_resume_from_saved_state_is_bit_identical(tmp_path, runs):
    system, model, full, half = runs
    path = tmp_path / "state.npz"
    save_state(path, half.state, system, CFG)
    state = load_state(path, system)
    assert state.epoch == 300
    assert _leaves_equal(state.model, half.state.model)
    assert _leaves_equal(state.opt_state, half.state.opt_state)
    assert _leaves_equal(state.track, half.state.track)
    assert np.array_equal(state.history.loss, half.history.loss)

    resumed = train(model, system, T_END, CFG, resume=state)
    assert resumed.stop_reason == full.stop_reason == "budget"
    assert resumed.epochs_run == 600 and resumed.best_epoch == full.best_epoch
    for name in ("loss", "residual", "energy", "gamma"):
        assert np.array_equal(getattr(resumed.history, name), getattr(full.history, name)), name
    assert _leaves_equal(resumed.model, full.model)
    assert _leaves_equal(resumed.final_model, full.final_model)

    # a state file is also a model checkpoint; a model checkpoint is not a state
    assert _leaves_equal(load_checkpoint(path).model, half.state.model)
    save_checkpoint(tmp_path / "plain.npz", full.model, system)
    with pytest.raises(CheckpointError, match="no training state"):
        load_state(tmp_path / "plain.npz", system)


# -------------------------------------------------------------- integrity checks
@pytest.fixture
def saved(tmp_path):
    """A saved checkpoint: (path, model)."""
    model = _small_model("rational_exp")
    path = tmp_path / "model.npz"
    save_checkpoint(path, model, harmonic_oscillator())
    return path, model


def test_flipped_byte_in_array_data_is_detected(saved):
    path, model = saved
    raw = bytearray(path.read_bytes())
    leaf = max(jax.tree_util.tree_leaves(model), key=lambda x: x.size)
    needle = np.asarray(leaf).tobytes()
    at = raw.find(needle)
    assert at >= 0 and raw.find(needle, at + 1) == -1
    raw[at + len(needle) // 2] ^= 0x01
    path.write_bytes(bytes(raw))
    assert "hash" in _load_error(path)


def test_altered_archive_with_valid_zip_checksums_is_detected(saved):
    path, _ = saved
    arrays = _read_npz(path)
    arrays["param_001"] = arrays["param_001"].copy()
    arrays["param_001"].flat[0] += 1.0
    _write_npz(path, arrays)
    assert "content hash mismatch" in _load_error(path)


def test_altered_meta_is_detected(saved):
    path, _ = saved
    arrays = _read_npz(path)
    meta = json.loads(arrays["meta"].tobytes())
    meta["extra"] = {"note": "edited"}
    arrays["meta"] = _meta_bytes(meta)
    _write_npz(path, arrays)
    assert "content hash mismatch" in _load_error(path)


@pytest.mark.parametrize("keep", ["half", "minus_one", "thirty"])
def test_truncated_file_is_refused(saved, keep):
    path, _ = saved
    data = path.read_bytes()
    n = {"half": len(data) // 2, "minus_one": len(data) - 1, "thirty": 30}[keep]
    path.write_bytes(data[:n])
    _load_error(path)


def _make_random(path):
    path.write_bytes(np.random.default_rng(0).bytes(4096))


def _make_text(path):
    path.write_text("this is not a checkpoint\n")


def _make_empty(path):
    path.write_bytes(b"")


def _make_npy(path):
    with open(path, "wb") as f:
        np.save(f, np.arange(5.0))


def _make_npz_without_meta(path):
    _write_npz(path, {"param_000": np.ones(3, np.float32)})


def _make_zip_of_text(path):
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("meta.npy", "hello")


def _make_bad_json(path):
    _write_npz(path, {"meta": np.frombuffer(b"{not json", dtype=np.uint8)})


def _make_bad_utf8(path):
    _write_npz(path, {"meta": np.frombuffer(b"\xff\xfe{}", dtype=np.uint8)})


def _make_meta_not_bytes(path):
    _write_npz(path, {"meta": np.zeros(3, np.float64)})


@pytest.mark.parametrize(
    "make",
    [_make_random, _make_text, _make_empty, _make_npy, _make_npz_without_meta, _make_zip_of_text,
     _make_bad_json, _make_bad_utf8, _make_meta_not_bytes],
)
def test_foreign_files_are_refused(tmp_path, make):
    path = tmp_path / "foreign.npz"
    make(path)
    _load_error(path)


def test_missing_file_and_directory(tmp_path):
    assert "no such file" in _load_error(tmp_path / "absent.npz")
    _load_error(tmp_path)


@pytest.mark.parametrize(
    "edit, expected",
    [
        (lambda m: m.update(format="something-else"), "format marker"),
        (lambda m: m.update(format_version=2), "newer"),
        (lambda m: m.update(format_version="1"), "format_version"),
        (lambda m: m.pop("content_sha256"), "content_sha256"),
    ],
)
def test_bad_meta_fields_are_refused(saved, edit, expected):
    path, _ = saved
    arrays = _read_npz(path)
    meta = json.loads(arrays["meta"].tobytes())
    edit(meta)
    arrays["meta"] = _meta_bytes(meta)
    _write_npz(path, arrays)
    assert expected in _load_error(path)


@pytest.mark.parametrize("change", ["width", "drop_leaf"])
def test_leaf_mismatch_is_refused(saved, change):
    """A consistent (re-hashed) file whose leaves do not fit its architecture."""
    path, _ = saved
    arrays = _read_npz(path)
    meta = json.loads(arrays.pop("meta").tobytes())
    meta.pop("content_sha256")
    if change == "width":
        meta["architecture"]["width"] = 9
    else:
        last = max(k for k in arrays if k.startswith("param_"))
        del arrays[last]
    meta["content_sha256"] = ckpt._content_hash(meta, arrays)
    arrays["meta"] = _meta_bytes(meta)
    _write_npz(path, arrays)
    assert "leaf mismatch" in _load_error(path)


# --------------------------------------------------------------- never unpickle
_UNPICKLED: list[str] = []


def _record_unpickling(tag):
    _UNPICKLED.append(tag)
    return tag


class _Trap:
    """Unpickling this object calls _record_unpickling: loading must never do it."""

    def __reduce__(self):
        return (_record_unpickling, ("unpickled",))


@pytest.mark.parametrize("with_checkpoint", [False, True])
def test_object_arrays_are_refused_without_unpickling(saved, with_checkpoint):
    path, _ = saved
    arrays = _read_npz(path) if with_checkpoint else {}
    trap = np.empty(1, dtype=object)
    trap[0] = _Trap()
    arrays["param_000" if with_checkpoint else "meta"] = trap
    _write_npz(path, arrays)  # np.savez pickles object arrays by default
    _UNPICKLED.clear()
    msg = _load_error(path)
    assert "object array" in msg
    assert _UNPICKLED == []


# ----------------------------------------------------------------- atomic write
def _save(path):
    return save_checkpoint(path, _small_model("tanh"), harmonic_oscillator())


def test_failure_while_writing_leaves_nothing(tmp_path, monkeypatch):
    def full_disk(f, *args, **kwargs):
        f.write(b"PK\x03\x04 partial archive")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    with pytest.raises(CheckpointError, match="No space left"):
        _save(tmp_path / "m.npz")
    assert os.listdir(tmp_path) == []


def test_interrupt_while_writing_leaves_nothing(tmp_path, monkeypatch):
    def interrupted(f, *args, **kwargs):
        f.write(b"PK\x03\x04 partial archive")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _save(tmp_path / "m.npz")
    assert os.listdir(tmp_path) == []


def test_failed_rename_keeps_the_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "m.npz"
    first = _save(path)
    before = path.read_bytes()

    def no_rename(src, dst):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "replace", no_rename)
    with pytest.raises(CheckpointError, match="Input/output error"):
        save_checkpoint(path, _small_model("rational_exp"), harmonic_oscillator())
    monkeypatch.undo()
    assert os.listdir(tmp_path) == ["m.npz"] and path.read_bytes() == before
    assert load_checkpoint(path).content_sha256 == first


def test_failed_rename_without_previous_file_leaves_nothing(tmp_path, monkeypatch):
    def no_rename(src, dst):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "replace", no_rename)
    with pytest.raises(CheckpointError):
        _save(tmp_path / "m.npz")
    monkeypatch.undo()
    assert os.listdir(tmp_path) == []


def test_save_into_missing_directory(tmp_path):
    with pytest.raises(CheckpointError, match="cannot write"):
        _save(tmp_path / "no" / "such" / "m.npz")


def test_save_with_its_arguments_swapped_is_one_line(tmp_path, ho):
    # save(solution, path), as numpy and torch order them, gave os.fspath's TypeError
    from atlasnn import save, solve
    from atlasnn.errors import CheckpointError

    sol = solve(ho, None, (0.0, 1.0))
    with pytest.raises(CheckpointError, match=r"save\(path, solution\)"):
        save(sol, tmp_path / "sol.npz")
    assert not list(tmp_path.iterdir())
