"""Each tox environment installs exactly its back ends (ILOCI_EXPECT_BACKENDS)."""

from __future__ import annotations

import os

import pytest

from iloci.errors import MissingBackendError
from iloci.plugins import get_registry

EXPECTED = os.environ.get("ILOCI_EXPECT_BACKENDS")


@pytest.mark.skipif(EXPECTED is None, reason="set by tox: ILOCI_EXPECT_BACKENDS")
def test_exactly_the_expected_backends_are_registered_and_available():
    expected = {n for n in EXPECTED.split(",") if n}
    expected |= {n for n in os.environ.get("ILOCI_EXPECT_EXTRA", "").split(",") if n}
    registry = get_registry()
    registered = {spec.name for spec in registry.specs()}
    assert registered == expected
    unavailable = {spec.name for spec in registry.specs() if not spec.available}
    assert not unavailable


def test_missing_first_party_backend_is_reported_cleanly():
    registry = get_registry()
    for kind, name in [("perceptual_model", "native-rnnpb"), ("perceptual_model", "torch-rnnpb"),
                       ("perceptual_model", "jax-rnnpb"),
                       ("clusterer", "sklearn"), ("simulator", "mujoco")]:
        if (kind, name) in registry:
            continue
        with pytest.raises(MissingBackendError, match=r"pip install \./plugins/iloci-"):
            registry.get(kind, name)
