"""Transfer learning from a short source interval to a long target interval.

The target model starts from the source's trained network θ and time scaling γ (same
architecture, same z0 and t0). For ATLAS-NN, γ is then frozen (the paper's scheme); ``thaw=True``
keeps it trainable instead (the paper's future work). The HNN baseline has no γ to freeze.
As in the authors' release, the source run's Adam state can be carried over (the moments of the
parameters that stay trainable).
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

from atlasnn.errors import ConfigError
from atlasnn.nn import TrialSolution
from atlasnn.systems import HamiltonianSystem
from atlasnn.training._records import TrainConfig, TrainResult, TrainState
from atlasnn.training._step import restrict_opt_state
from atlasnn.training._train import train_batch


def check_same_architecture(source: TrialSolution, architecture: dict[str, Any]) -> None:
    """Raise a one-line error naming the first field where ``architecture`` differs from the source."""
    have = source.architecture()
    for key, want in architecture.items():
        if key in have and have[key] != want:
            raise ConfigError(
                f"target architecture differs from the source: {key} = {want!r} but the source has {have[key]!r}"
            )


def transfer(
    source: TrainResult,
    system: HamiltonianSystem,
    T: float,
    config: TrainConfig,
    *,
    thaw: bool = False,
    carry_adam: bool = True,
    architecture: dict[str, Any] | None = None,
    desc: str = "target",
    resume: TrainState | None = None,
    on_chunk: Callable[[TrainState], None] | None = None,
) -> TrainResult:
    """Train a target model on [t0, T] starting from a trained source run.

    Args:
        source: the source run (its returned ``model`` gives θ and γ; its Adam state is carried
            when ``carry_adam``).
        system: the Hamiltonian system (the same one the source was trained on).
        T: the end of the target interval.
        config: the target's training config; its ``freeze_gamma`` is overridden by ``thaw``.
        thaw: keep γ trainable in the target task (default: frozen).
        carry_adam: start from the source's Adam moments (the release does).
        architecture: the target's intended architecture (width, depth, ...); a mismatch with the
            source is an error.
        resume: passed to [`train`][atlasnn.training.train]: continue an interrupted target run from
            its saved ``TrainState``.
        on_chunk: passed to [`train`][atlasnn.training.train]: a per-chunk callback.
    """
    return transfer_from(
        source.model, source.opt_state, system, T, config, thaw=thaw, carry_adam=carry_adam,
        architecture=architecture, desc=desc, resume=resume, on_chunk=on_chunk,
    )


def transfer_from(
    model: TrialSolution,
    opt_state: Any,
    system: HamiltonianSystem,
    T: float,
    config: TrainConfig,
    *,
    thaw: bool = False,
    carry_adam: bool = True,
    architecture: dict[str, Any] | None = None,
    desc: str = "target",
    resume: TrainState | None = None,
    on_chunk: Callable[[TrainState], None] | None = None,
) -> TrainResult:
    """:func:`transfer` from a source model and its final Adam state instead of a TrainResult.

    This is what a resumed run uses: the source's returned model comes from its checkpoint
    (:func:`~atlasnn.checkpoint._single.load_checkpoint`) and its Adam state from its saved final
    :class:`~atlasnn.training._records.TrainState` (:func:`~atlasnn.checkpoint._single.load_state`); the target then
    starts exactly as it would have in the uninterrupted run. ``opt_state`` may be ``None`` when
    ``carry_adam`` is false or ``resume`` is given.
    """
    callback = None if on_chunk is None else (lambda states: on_chunk(states[0]))
    return transfer_batch([model], [opt_state], system, T, [config], thaw=thaw, carry_adam=carry_adam,
                          architecture=architecture, desc=desc, resumes=[resume], on_chunk=callback)[0]


def transfer_batch(
    models: Sequence[TrialSolution],
    opt_states: Sequence[Any],
    system: HamiltonianSystem,
    T: float,
    configs: Sequence[TrainConfig],
    *,
    thaw: bool = False,
    carry_adam: bool = True,
    architecture: dict[str, Any] | None = None,
    desc: str = "target",
    resumes: Sequence[TrainState | None] | None = None,
    on_chunk: Callable[[list[TrainState]], None] | None = None,
) -> list[TrainResult]:
    """:func:`transfer_from` for several sources (e.g. the seeds of one model) trained as one
    compiled program (:func:`~atlasnn.training._train.train_batch`): one source model, Adam state and
    target config per run."""
    resumes = list(resumes) if resumes is not None else [None] * len(models)
    starts, cfgs = [], []
    for model, opt_state, config, resume in zip(models, opt_states, configs, resumes):
        if architecture:
            check_same_architecture(model, architecture)
        if model.state_dim != system.state_dim:
            raise ConfigError(
                f"source model has state dimension {model.state_dim}, system {system.name!r} has {system.state_dim}"
            )
        cfg = config.replace(freeze_gamma=not thaw)
        start = None
        if carry_adam and resume is None:
            if opt_state is None:
                raise ConfigError("carry_adam needs the source run's Adam state (opt_state is None)")
            start = restrict_opt_state(opt_state, model, cfg.freeze_gamma)
        starts.append(start)
        cfgs.append(cfg)
    return train_batch(list(models), system, T, cfgs, opt_states=starts, resumes=resumes, desc=desc,
                       on_chunk=on_chunk)
