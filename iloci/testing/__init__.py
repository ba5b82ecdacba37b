"""Conformance suite for iloci components, in the spirit of sklearn's ``check_estimator``.

A plugin author proves a component behaves with::

    from iloci.testing import check_component
    check_component(lambda seed: MyTeacher(seed=seed), "teacher")

or, one pytest test per check::

    from iloci.testing import parametrize_with_checks

    @parametrize_with_checks([("teacher", lambda seed: MyTeacher(seed=seed))])
    def test_conformance(component, check):
        check(component)

``make(seed) -> component`` builds a fresh instance; checks build as many as
they need (determinism and state round trips compare two). The checks per
interface are in :data:`iloci.testing.checks.CHECKS`: protocol methods
present, shapes and dtypes, seeded determinism, state round trip through a
pickle-free file, batch-vs-single consistency, and clear iloci errors on bad
input. Robot presets (kind ``robot``) have their own
(:mod:`iloci.testing.robots`): the description's members, joints and limits,
``describe()`` as JSON, two builds alike; and
:func:`~iloci.testing.robots.check_registration` checks that what the
registration states (``joints``, ``plane``) is true.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from iloci.errors import IlociError
from iloci.plugins import get_registry
from iloci.registry import validate_params
from iloci.testing.checks import CHECKS, Factory

__all__ = ["CHECKS", "ConformanceError", "CheckResult", "check_component",
           "parametrize_with_checks", "registry_factory"]


@dataclass(frozen=True)
class CheckResult:
    """Outcome of one check."""

    check: str
    passed: bool
    message: str = ""


class ConformanceError(IlociError, AssertionError):
    """One or more conformance checks failed; ``results`` lists every check.

    An :class:`~iloci.errors.IlociError` (as every error iloci raises on
    purpose) and an ``AssertionError`` (a failed check in a test suite).
    """

    def __init__(self, kind: str, results: Sequence[CheckResult]) -> None:
        self.kind = kind
        self.results = list(results)
        failed = [r for r in results if not r.passed]
        lines = [f"{len(failed)} of {len(results)} {kind} conformance checks failed:"]
        lines += [f"  - {r.check}: {r.message}" for r in failed]
        super().__init__("\n".join(lines))

    @property
    def failed(self) -> list[str]:
        return [r.check for r in self.results if not r.passed]


def _as_factory(component: Any) -> Factory:
    if isinstance(component, type):  # a class: build with the seed when it takes one
        import inspect
        takes_seed = "seed" in inspect.signature(component).parameters
        return lambda seed: component(seed=seed) if takes_seed else component()
    if callable(component) and not any(hasattr(component, m) for m in
                                       ("feedback", "cluster", "train", "solve", "execute")):
        import inspect
        try:
            takes_none = not inspect.signature(component).parameters
        except (TypeError, ValueError):
            takes_none = False
        # a factory taking nothing (a robot preset's): the seed is not passed
        return (lambda seed: component()) if takes_none else component
    # A ready-made instance: every "fresh" build returns the same object, so
    # determinism checks are weaker; pass a factory when you can.
    return lambda seed: component


def check_component(component: Any, kind: str, *, checks: Iterable[str] | None = None,
                    raise_on_failure: bool = True) -> list[CheckResult]:
    """Run the conformance checks of ``kind`` on a component.

    Parameters
    ----------
    component : callable or object
        ``make(seed) -> instance`` (preferred), or an instance.
    kind : str
        One of ``perceptual_model``, ``clusterer``, ``teacher``, ``ik``,
        ``simulator``, ``robot`` (a preset: ``make()`` returns its
        description; see also :func:`iloci.testing.robots.check_registration`).
    checks : iterable of str, optional
        Names of the checks to run (default: all of the kind).
    raise_on_failure : bool
        Raise :class:`ConformanceError` listing every failed check.

    Returns
    -------
    list of CheckResult
    """
    if kind not in CHECKS:
        raise ValueError(f"unknown kind {kind!r}; kinds are {', '.join(CHECKS)}")
    make = _as_factory(component)
    wanted = set(checks) if checks is not None else None
    results = []
    for check in CHECKS[kind]:
        if wanted is not None and check.__name__ not in wanted:
            continue
        try:
            check(make)
        except Exception as exc:  # every failure is reported, not just the first
            results.append(CheckResult(check.__name__, False,
                                       f"{type(exc).__name__}: {exc}".strip()))
        else:
            results.append(CheckResult(check.__name__, True))
    if raise_on_failure and any(not r.passed for r in results):
        raise ConformanceError(kind, results)
    return results


def registry_factory(kind: str, name: str, **params: Any) -> Factory:
    """``make(seed)`` building registered component ``name`` with ``params``."""

    registry = get_registry()
    spec = registry.get(kind, name)
    validated = validate_params(spec, params)

    def make(seed: int) -> Any:
        return registry.build(kind, name, validated, seed=seed)

    make.__name__ = f"{kind}:{name}"
    return make


def parametrize_with_checks(components: Sequence[tuple[str, Callable[[int], Any]]]):
    """pytest decorator: one test per (component, check).

    Parameters
    ----------
    components : sequence of (kind, make)

    The decorated test receives ``component`` (the factory) and ``check``
    (call it as ``check(component)``).
    """
    import pytest

    params = []
    for kind, make in components:
        label = getattr(make, "__name__", kind)
        for check in CHECKS[kind]:
            params.append(pytest.param(make, check, id=f"{label}-{check.__name__}"))
    return pytest.mark.parametrize("component, check", params)
