"""Every installed component of iloci's own passes the conformance suite.

Parametrized over what the registry holds, so each tox env checks exactly
the back ends it installed (tests/test_matrix.py checks that those are the
expected ones). Built through the registry, as a config would build them,
with small networks so the checks stay quick.
"""

from __future__ import annotations

import io

import pytest

from iloci.docgen import first_party
from iloci.plugins import get_registry
from iloci.testing import check_component, registry_factory
from iloci.testing.robots import check_registration

#: Smaller settings where the defaults would make the checks slow.
SMALL = {
    ("perceptual_model", "native-rnnpb"): {"hidden": 20, "context": 10, "epochs": 10,
                                           "recognition_steps": 20},
    ("perceptual_model", "torch-rnnpb"): {"hidden": 20, "context": 10, "epochs": 10,
                                          "recognition_steps": 20},
    ("perceptual_model", "jax-rnnpb"): {"hidden": 20, "context": 10, "epochs": 10,
                                        "recognition_steps": 20},
}


def _console(seed):
    # a person who always answers "y"; the suite cannot sit at a terminal
    from iloci.teachers import ConsoleTeacher
    return ConsoleTeacher(picture_dir="", stdin=io.StringIO("y\n" * 1000),
                          stdout=io.StringIO())


def _cases():
    cases = []
    registry = get_registry()
    for spec in [*registry.specs(), *registry.specs("robot")]:
        marks = []
        if not first_party(spec):
            marks.append(pytest.mark.skip(reason=f"third-party ({spec.distribution}): "
                                                 "tested by its own distribution"))
        elif not spec.available:
            marks.append(pytest.mark.skip(reason=f"missing {', '.join(spec.missing())}"))
        cases.append(pytest.param(spec.kind, spec.name, marks=marks,
                                  id=f"{spec.kind}:{spec.name}"))
    return cases


@pytest.mark.parametrize("kind, name", _cases())
def test_installed_component_conforms(kind, name):
    if (kind, name) == ("teacher", "console"):
        make = _console
    else:
        make = registry_factory(kind, name, **SMALL.get((kind, name), {}))
    check_component(make, kind)
    if kind == "robot":  # what its registration states is true
        check_registration(get_registry().get(kind, name), make(0))
