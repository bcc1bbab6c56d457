"""A task: the trainings of one column (scheme and model) for a batch of seeds."""

from __future__ import annotations

from dataclasses import dataclass

from atlasnn.experiments._schemes import SCHEMES

__all__ = ["Task"]


@dataclass(frozen=True)
class Task:
    """The trainings of one column for a batch of seeds, trained together as one program.

    ``role`` names the scheme (a key of :data:`~atlasnn.experiments._schemes.SCHEMES`: "short",
    "baseline", "transfer", "march"), ``model`` the model (a key of :data:`atlasnn.nn.MODELS`).
    """

    role: str
    model: str
    seeds: tuple[int, ...]

    @property
    def column(self) -> str:
        """The table column this task's trainings fill."""
        return SCHEMES[self.role].column(self.model)

    @property
    def state_names(self) -> tuple[str, ...]:
        """The names of the states a training of this task keeps while unfinished (its column's,
        and a transfer source's)."""
        return (self.column, *SCHEMES[self.role].extra_states(self.model))

    @property
    def seed(self) -> int:
        """The seed of a one-seed task."""
        if len(self.seeds) != 1:
            raise ValueError(f"task {self.column} holds seeds {list(self.seeds)}, not one")
        return self.seeds[0]

    def one(self, seed: int) -> "Task":
        """The one-seed task of ``seed`` (records and state files are kept per seed)."""
        return Task(self.role, self.model, (seed,))

    def trainings(self) -> list["Task"]:
        return [self.one(s) for s in self.seeds]
