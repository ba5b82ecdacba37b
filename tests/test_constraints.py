"""Config constraints declared as data (iloci.constraints): one validator, bad values derived."""

from __future__ import annotations

import pytest

from iloci.config import _PLAIN_SECTIONS, load_config
from iloci.constraints import Interval, Options, bad_values, constraints_of
from iloci.errors import ConfigError
from iloci.registry import validate_dataclass

BAD = [(sec, key, value) for sec, cls in _PLAIN_SECTIONS.items()
       for key, value in bad_values(cls)]


def test_the_sections_declare_their_constraints():
    declared = {sec: constraints_of(cls) for sec, cls in _PLAIN_SECTIONS.items()}
    assert {"k_cutoff", "num_threshold", "decision", "tilts"} <= set(declared["learner"])
    assert {"folds", "seed", "train_fraction", "split"} <= set(declared["evaluation"])
    assert len(BAD) >= 30


@pytest.mark.parametrize("section, key, value", BAD)
def test_every_declared_constraint_refuses_the_values_outside_it(section, key, value):
    with pytest.raises(ConfigError, match=rf"\[{section}\]: {key} must be ") as e:
        load_config({section: {key: value}})
    assert e.value.key == f"{section}.{key}"


def test_the_defaults_meet_their_constraints():
    for sec, cls in _PLAIN_SECTIONS.items():
        assert validate_dataclass(cls, {}, section=sec) == cls()


def test_interval_and_options_say_what_they_take():
    assert Interval(0).describe() == ">= 0" and Interval(0, closed="right").describe() == "> 0"
    assert Interval(0, 1, closed="left").describe() == "in [0, 1)"
    assert Interval(2, 7, integer=True, note="why").describe() == "in 2..7 (why)"
    assert Interval(0, 90, closed="right", each=True).describe() == "numbers each in (0, 90]"
    assert Options("a", "b").describe() == "'a' or 'b'"
    assert Options("a", "b", "c").describe() == "one of 'a', 'b', 'c'"
    assert not Interval(0).holds(True) and not Interval(0).holds("1")
    assert Interval(0, 1, closed="neither").bad(0.5) == [0, 1]
    assert Interval(3).bad(5) == [2]
    assert Interval(0, 90, each=True).bad((8.0,)) == [(-0.5,), (90.5,)]
