"""The path reading (``resample = "arc_length"``) is the same however a person draws.

Each invariance on real LASA demonstrations (one of each of the 26 shapes):
the network's sensory input -- the plane displacements ``(dy, dz)`` per
step, scaled as the encoder scales them (by the largest of the
demonstration's own) -- of the perturbed demonstration against the
original's. The tolerance is stated per test as the RMS difference over
the 49 steps, as a fraction of that largest displacement; the worst
demonstration must meet it. The paper's time-based reading fails the
pace and rest tests, so they can fail.

Bad input a person's device brings (screen coordinates, milliseconds, a
tap) has one test each.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from iloci.config import ConfigError, SensorimotorConfig, load_config
from iloci.data import load_lasa
from iloci.errors import InvalidDemonstrationError, TimeUnitWarning
from iloci.evaluation import perturb as P
from iloci.interfaces import Demonstration
from iloci.sensorimotor.pipeline import preprocessed

PAPER = SensorimotorConfig(resample="time", rest_tolerance=0.0)
PATH = SensorimotorConfig(resample="arc_length", rest_tolerance=0.01)


@pytest.fixture(scope="module")
def demos():
    return [d for d in load_lasa() if d.index == 0]


def _input(demo, cfg=PATH):
    return np.diff(preprocessed(demo, cfg), axis=0)


def _worst_rms(demos, change, cfg=PATH):
    worst = 0.0
    for d in demos:
        ref = _input(d, cfg)
        err = (_input(change(d), cfg) - ref) / np.abs(ref).max()
        worst = max(worst, float(np.sqrt(np.mean(err ** 2))))
    return worst


@pytest.mark.parametrize("points, tolerance", [(25, 0.10), (100, 0.03), (10_000, 0.01)])
def test_sampling_rate(demos, points, tolerance):
    # 25 samples of a LASA shape lose detail no resampling brings back (the
    # worst, a sharp-cornered shape, is at 0.07); 10 000 lose nothing
    assert _worst_rms(demos, lambda d: P.resample_count(d, points)) <= tolerance


def test_pace(demos):
    for kind in ("slow_fast", "fast_slow"):
        def warp(d, kind=kind):
            return P.time_warp(d, kind)
        assert _worst_rms(demos, warp) <= 0.02
        assert _worst_rms(demos, warp, PAPER) > 0.2


def test_pen_rests(demos):
    assert _worst_rms(demos, P.pen_rests) <= 1e-9  # trimmed away exactly
    assert _worst_rms(demos, lambda d: P.pen_rests(d, 0.25, "middle")) <= 0.02
    assert _worst_rms(demos, P.pen_rests, PAPER) > 0.2


def test_jitter_is_smoothed_along_the_path(demos):
    rng = np.random.default_rng(0)
    smoothed = _worst_rms(demos, lambda d: P.jitter(d, 0.02, rng))
    rng = np.random.default_rng(0)
    raw = _worst_rms(demos, lambda d: P.jitter(d, 0.02, rng),
                     SensorimotorConfig(resample="arc_length", smoothing=0.0))
    assert smoothed <= 0.15 and smoothed < raw / 3


def test_uniform_scale_and_translation(demos):
    assert _worst_rms(demos, lambda d: P.scale(d, 0.01)) <= 1e-9
    assert _worst_rms(demos, lambda d: P.scale(d, 1000.0)) <= 1e-9


def test_screen_coordinates_with_y_down(demos):
    for cfg in (PATH, PAPER):
        down = dataclasses.replace(cfg, y_axis="down")
        for d in demos[:5]:
            flipped = Demonstration(d.positions * [1.0, -1.0] + [0.0, 900.0], d.times,
                                    shape=d.shape)
            assert np.allclose(preprocessed(flipped, down), preprocessed(d, cfg), atol=1e-12)
            assert not np.allclose(preprocessed(flipped, cfg), preprocessed(d, cfg), atol=1e-3)


def test_millisecond_time_stamps_warn_with_the_likely_unit(demos):
    d = demos[0]
    with pytest.warns(TimeUnitWarning, match="look like milliseconds") as record:
        Demonstration(d.positions, d.times * 1000.0)
    assert "Divide them by 1000" in str(record[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Demonstration(d.positions, d.times)          # seconds: silent
        Demonstration(d.positions)                   # sample numbers: silent


def test_a_too_short_stroke_is_a_clear_error(demos):
    d = demos[0]
    tap = Demonstration(d.positions[::300], d.times[::300])          # 4 samples
    with pytest.raises(InvalidDemonstrationError, match=r"4 samples.*at least 5"):
        preprocessed(tap, PATH)
    rested = P.pen_rests(tap, 0.5)                                     # 4 + 2 x 2 samples
    with pytest.raises(InvalidDemonstrationError, match="4 samples once the pen's rests are "
                       r"trimmed \(from 8\); at least 5"):
        preprocessed(rested, PATH)
    assert preprocessed(Demonstration(d.positions[::200], d.times[::200]), PATH).shape == (50, 2)
    with pytest.raises(InvalidDemonstrationError, match="at least 12"):
        preprocessed(Demonstration(d.positions[::100], d.times[::100]),
                     SensorimotorConfig(resample="arc_length", min_points=12))


def test_new_settings_are_validated():
    for bad in ({"y_axis": "left"}, {"smoothing": -0.1}, {"rest_tolerance": 0.7},
                {"min_points": 2}):
        with pytest.raises(ConfigError):
            load_config({"sensorimotor": bad})
    with pytest.raises(ConfigError, match="order"):
        load_config({"evaluation": {"order": "random"}})
