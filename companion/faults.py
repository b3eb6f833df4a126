"""A test-only fault hook: make one stage of a recovery raise, to prove the fail-safe that catches the
companion's own defects (companion/recovery/machine.py, ``Recovery._fail_safe``).

Off unless the environment variable ``LANDFALL_TEST_FAULT`` names a stage, alone (``rank``: the first
time the recovery reaches it) or with a round (``confirm:2``: the first time in round 2). The stage
then raises :class:`InjectedFault` once, as a defect anywhere in that stage would. Nothing else reads
the variable, no configuration file can set it, and it never fires twice: end-to-end tests use it to
show that every stage's defect still ends in a graded touchdown.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["ENV", "STAGES", "FaultHook", "InjectedFault"]

ENV = "LANDFALL_TEST_FAULT"
STAGES = ("acquire", "surface_id", "rank", "ipm", "move", "confirm", "descend", "land")


class InjectedFault(RuntimeError):
    """Raised by a stage the fault hook names (tests only)."""


@dataclass
class FaultHook:
    """Where to raise (``stage``, and ``round`` when given); ``None`` stage: never."""

    stage: str | None = None
    round: int | None = None
    fired: bool = False

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> FaultHook:
        """The hook ``LANDFALL_TEST_FAULT`` asks for (off when unset or empty).

        Raises:
            ValueError: an unknown stage or a round that is not a positive integer.
        """
        text = (os.environ if env is None else env).get(ENV, "").strip()
        if not text:
            return cls()
        stage, _, rnd = text.partition(":")
        if stage not in STAGES:
            raise ValueError(f"{ENV}: unknown stage {stage!r}; stages: {', '.join(STAGES)}")
        if rnd and not (rnd.isdigit() and int(rnd) > 0):
            raise ValueError(f"{ENV}: the round after ':' must be a positive integer, got {rnd!r}")
        return cls(stage, int(rnd) if rnd else None)

    def check(self, stage: str, round_: int) -> None:
        """Raise :class:`InjectedFault` if this is the stage (and round) asked for, the first time."""
        if self.stage != stage or self.fired or (self.round is not None and self.round != round_):
            return
        self.fired = True
        raise InjectedFault(f"test fault injected in stage {stage!r} (round {round_}, {ENV})")
