"""iloci plugin: the ``replay`` teacher (recorded human feedback from a CSV file).

This module is imported when iloci loads its plugins, so it imports nothing
but iloci and the standard library; the teacher itself is in
``iloci_replay.teacher``, imported when a config builds it.
"""

from __future__ import annotations

from dataclasses import dataclass

from iloci import hookimpl


@dataclass(frozen=True)
class ReplayParams:
    """Keys of the ``[teacher]`` section when ``name = "replay"``."""

    #: CSV file with columns demo, attempt, feedback.
    file: str = "feedback.csv"
    #: Feedback for an answer not in the file: +1, -1, or 0 for an error.
    default: int = 0

    def validate(self) -> None:
        if self.default not in (-1, 0, 1):
            raise ValueError(f"default must be -1, 0 or 1, got {self.default}")


@hookimpl
def iloci_register_teachers(registry) -> None:
    registry.add("replay", "iloci_replay.teacher:ReplayTeacher", params=ReplayParams,
                 summary="replays recorded human feedback from a CSV file")
