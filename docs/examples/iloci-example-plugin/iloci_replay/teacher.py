"""The replay teacher."""

from __future__ import annotations

import csv
from pathlib import Path

from iloci.errors import ConfigError, FeedbackError
from iloci.interfaces import Demonstration, Response


class ReplayTeacher:
    """Answers with recorded feedback, keyed by (demonstration, attempt).

    Parameters
    ----------
    file : str
        CSV with header ``demo,attempt,feedback``.
    default : int
        Feedback for unrecorded answers (+1 or -1), or 0 to raise
        :class:`iloci.errors.FeedbackError`.
    """

    def __init__(self, file: str = "feedback.csv", default: int = 0) -> None:
        self.file = file
        self.default = default
        self.records = self._read(Path(file))

    @staticmethod
    def _read(path: Path) -> dict[tuple[str, int], int]:
        try:
            with path.open(newline="") as f:
                rows = list(csv.DictReader(f))
        except FileNotFoundError:
            raise ConfigError(f"replay teacher: feedback file {path} not found; record one "
                              "with columns demo,attempt,feedback.") from None
        records = {}
        for n, row in enumerate(rows, start=2):
            try:
                key = (row["demo"], int(row["attempt"]))
                value = int(row["feedback"])
            except (KeyError, TypeError, ValueError):
                raise ConfigError(f"{path}:{n}: expected columns demo,attempt,feedback with "
                                  f"integer attempt and feedback, got {row}.") from None
            if value not in (1, -1):
                raise ConfigError(f"{path}:{n}: feedback must be 1 or -1, got {value}.")
            records[key] = value
        return records

    def feedback(self, demo: Demonstration, response: Response) -> int:
        value = self.records.get((demo.key, response.attempt), self.default)
        if value == 0:
            raise FeedbackError(f"replay teacher: no recorded feedback for {demo.key} "
                                f"attempt {response.attempt} in {self.file}; record it or "
                                "set default = 1 or -1.")
        return value
