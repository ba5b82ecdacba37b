"""Constraints on settings, declared as data beside each field (as scikit-learn does).

A schema field says what values it takes next to its default::

    k_cutoff: float = constrained(0.5, Interval(0, None))
    decision: str = constrained("pb_distance", Options("pb_distance", "reproduction"))

:func:`check_constraints` is the one validator: it checks every constrained
field of a schema instance and writes the message (``"k_cutoff must be >= 0,
got -0.5"``). :func:`bad_values` derives, from the same declarations, values
each field must refuse (the tests feed them to :func:`iloci.load_config`). A
rule that ties two fields together stays in the schema's ``validate()``.
"""

from __future__ import annotations

from collections.abc import Iterator
import dataclasses
from dataclasses import dataclass
import math
from typing import Any

__all__ = ["Interval", "Options", "bad_values", "check_constraints", "constrained",
           "constraints_of", "violations"]


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else str(x)


@dataclass(frozen=True)
class Interval:
    """A number in a range; ``None`` leaves a side open-ended.

    Parameters
    ----------
    lo, hi : float or None
        Bounds.
    closed : str
        ``"both"``, ``"left"``, ``"right"`` or ``"neither"``: which bounds
        belong to the range.
    each : bool
        The field is a tuple of numbers, each in the range.
    integer : bool
        Written ``lo..hi`` (a closed range of integers).
    note : str
        Appended to the message (what the number is, why the range).
    """

    lo: float | None = None
    hi: float | None = None
    closed: str = "both"
    each: bool = False
    integer: bool = False
    note: str = ""

    def holds(self, value: Any) -> bool:
        values = value if self.each else (value,)
        return all(self._one(v) for v in values)

    def _one(self, v: Any) -> bool:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return False
        if self.lo is not None:
            if v < self.lo or (v == self.lo and self.closed in ("right", "neither")):
                return False
        if self.hi is not None:
            if v > self.hi or (v == self.hi and self.closed in ("left", "neither")):
                return False
        return True

    def describe(self) -> str:
        lo_in = self.closed in ("both", "left")
        hi_in = self.closed in ("both", "right")
        if self.hi is None and self.lo is not None:
            text = f"{'>=' if lo_in else '>'} {_fmt(self.lo)}"
        elif self.lo is None and self.hi is not None:
            text = f"{'<=' if hi_in else '<'} {_fmt(self.hi)}"
        elif self.lo is None or self.hi is None:
            text = "a number"
        elif self.integer and lo_in and hi_in:
            text = f"in {_fmt(self.lo)}..{_fmt(self.hi)}"
        else:
            text = (f"in {'[' if lo_in else '('}{_fmt(self.lo)}, {_fmt(self.hi)}"
                    f"{']' if hi_in else ')'}")
        if self.each:
            text = f"numbers each {text}"
        return f"{text} ({self.note})" if self.note else text

    def bad(self, default: Any) -> list[Any]:
        """Values just outside the range (of the default's type)."""
        step = 1 if isinstance(default, int) or (self.each and all(
            isinstance(x, int) for x in default)) else 0.5
        out = []
        if self.lo is not None:
            out.append(self.lo - step if self.closed in ("both", "left") else self.lo)
        if self.hi is not None:
            out.append(self.hi + step if self.closed in ("both", "right") else self.hi)
        return [(v,) for v in out] if self.each else out


@dataclass(frozen=True)
class Options:
    """One of a fixed set of values."""

    values: tuple[Any, ...]

    def __init__(self, *values: Any) -> None:
        object.__setattr__(self, "values", tuple(values))

    def holds(self, value: Any) -> bool:
        return value in self.values

    def describe(self) -> str:
        shown = [repr(v) for v in self.values]
        if len(shown) == 2:
            return f"{shown[0]} or {shown[1]}"
        return "one of " + ", ".join(shown)

    def bad(self, default: Any) -> list[Any]:
        return ["no-such-" + str(default)] if isinstance(default, str) else []


def constrained(default: Any, *constraints: Interval | Options) -> Any:
    """A dataclass field with ``default`` and the constraints its values must meet."""
    return dataclasses.field(default=default, metadata={"constraints": constraints})


def constraints_of(cls: type) -> dict[str, tuple[Interval | Options, ...]]:
    """Field name -> its declared constraints, for a schema dataclass."""
    return {f.name: f.metadata["constraints"] for f in dataclasses.fields(cls)
            if "constraints" in f.metadata}


def violations(obj: Any) -> list[tuple[str, str]]:
    """(field, message) of each constrained field of ``obj`` out of its constraints."""
    out = []
    for name, cons in constraints_of(type(obj)).items():
        value = getattr(obj, name)
        for c in cons:
            if not c.holds(value):
                shown = list(value) if isinstance(value, tuple) else value
                out.append((name, f"{name} must be {c.describe()}, got {shown!r}"))
                break
    return out


def check_constraints(obj: Any) -> None:
    """Check every constrained field of ``obj``, a schema dataclass instance.

    Raises
    ------
    ValueError
        ``"NAME must be DESCRIPTION, got VALUE"`` for the first field out of
        its constraints (:func:`iloci.registry.validate_dataclass` turns it
        into a ConfigError naming the section and key).
    """
    for _, message in violations(obj)[:1]:
        raise ValueError(message)


def bad_values(cls: type) -> Iterator[tuple[str, Any]]:
    """(field, value) pairs the declared constraints of ``cls`` refuse, for tests."""
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    for name, cons in constraints_of(cls).items():
        for c in cons:
            for v in c.bad(defaults[name]):
                if not (isinstance(v, float) and math.isnan(v)):
                    yield name, v
