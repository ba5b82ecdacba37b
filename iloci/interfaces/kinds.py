"""The one table of component kinds: protocol, config section, label, registration hook.

The registry, the config, the plugin manager and :func:`iloci.build` read
:data:`COMPONENT_KINDS`; :data:`EXTRA_KINDS` holds the kinds registered like
components but chosen outside the config's sections (fold executors, robots).
"""

from __future__ import annotations

import inspect

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any



from iloci.interfaces.clusterer import Clusterer
from iloci.interfaces.executor import FoldExecutor
from iloci.interfaces.ik import IKSolver
from iloci.interfaces.perceptual_model import PerceptualModel
from iloci.interfaces.robot import RobotDescription
from iloci.interfaces.simulator import Simulator
from iloci.interfaces.teacher import Teacher

__all__ = ["ComponentKind", "COMPONENT_KINDS", "KINDS", "OPTIONAL_MEMBERS", "EXTRA_KINDS",
           "ALL_KINDS", "unmet_members"]


@dataclass(frozen=True)
class ComponentKind:
    """One kind of component: its protocol, config section and registration hook.

    Attributes
    ----------
    name : str
        The kind, which is also its config section (``[ik]``) and the
        section's keyword of :func:`iloci.build` (``ik=my_solver``).
    protocol : type
        The :class:`typing.Protocol` its components satisfy.
    label : str
        How messages name it (``"IK solver"``).
    hook : str
        The :mod:`iloci.hookspecs` hook through which plugins register it.
    optional : bool
        Whether a config may leave it out with ``name = "none"``.
    facts : tuple of str
        What a registration of this kind states besides its factory, for the
        listings (a robot's ``joints`` and ``plane``): keyword arguments of
        ``registry.add``, each required.
    """

    name: str
    protocol: type
    label: str
    hook: str
    optional: bool = False
    facts: tuple[str, ...] = ()

    @property
    def label_article(self) -> str:
        """The label with its article: ``"an IK solver"``, ``"a teacher"``."""
        return ("an " if self.label[0].lower() in "aeiou" else "a ") + self.label


#: Every component kind, in config order: the one table the registry, the
#: config, the plugin manager and :func:`iloci.build` read.
COMPONENT_KINDS: Mapping[str, ComponentKind] = MappingProxyType({k.name: k for k in (
    ComponentKind("perceptual_model", PerceptualModel, "perceptual model",
                  "iloci_register_perceptual_models"),
    ComponentKind("clusterer", Clusterer, "clusterer", "iloci_register_clusterers"),
    ComponentKind("teacher", Teacher, "teacher", "iloci_register_teachers"),
    ComponentKind("ik", IKSolver, "IK solver", "iloci_register_ik_solvers"),
    ComponentKind("simulator", Simulator, "simulator", "iloci_register_simulators",
                  optional=True),
)})

#: The kinds' names (:data:`COMPONENT_KINDS` keys), in config order.
KINDS: tuple[str, ...] = tuple(COMPONENT_KINDS)


#: Protocol name -> members an implementation may leave out: an executor
#: driving a real arm renders nothing (``iloci draw`` then cannot picture it).
#: :func:`unmet_members` does not require them.
OPTIONAL_MEMBERS: Mapping[str, tuple[str, ...]] = MappingProxyType({"Simulator": ("render",)})


def unmet_members(obj: Any, protocol: type) -> list[str]:
    """Members of ``protocol`` that ``obj`` lacks, or has but cannot call, sorted.

    Structural, like ``isinstance(obj, protocol)``, but it names what is
    missing and also requires the protocol's methods to be callable. An
    empty list means ``obj`` satisfies the protocol's shape (not that it
    behaves: see :mod:`iloci.testing` for that).
    """
    optional = set(OPTIONAL_MEMBERS.get(protocol.__name__, ()))
    attributes = set(vars(protocol).get("__annotations__", {})) - optional
    methods = {n for n, v in vars(protocol).items()
               if callable(v) and not n.startswith("_")} - optional
    out = [n for n in attributes - methods if not hasattr(obj, n)]
    out += [n for n in methods if not callable(getattr(obj, n, None))]
    for n in methods:
        if callable(getattr(obj, n, None)):
            fault = _call_fault(n, vars(protocol)[n], getattr(obj, n))
            if fault:
                out.append(fault)
    return sorted(out)


def _call_fault(name: str, spec: Any, method: Any) -> str:
    """``""`` if ``method`` can be called as the protocol's ``spec`` is (its required
    positional arguments), else what it lacks, e.g. ``"feedback taking (demo, response)"``."""
    try:
        wanted = [p for p in list(inspect.signature(spec).parameters.values())[1:]
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
                  and p.default is p.empty]
        inspect.signature(method).bind(*[None] * len(wanted))
    except (TypeError, ValueError) as exc:  # ValueError: no signature to read (a builtin)
        if isinstance(exc, ValueError):
            return ""
        return f"{name} taking ({', '.join(p.name for p in wanted)})"
    return ""


#: Kinds registered like components but chosen outside the config's
#: component sections: fold executors (``iloci evaluate --executor NAME``)
#: and robot presets (``[robot] name``, a plain section).
EXTRA_KINDS: Mapping[str, ComponentKind] = MappingProxyType({k.name: k for k in (
    ComponentKind("executor", FoldExecutor, "fold executor", "iloci_register_executors",
                  optional=True),
    ComponentKind("robot", RobotDescription, "robot", "iloci_register_robots",
                  facts=("joints", "plane")),
)})

#: Every kind the registry holds: the components, then :data:`EXTRA_KINDS`.
ALL_KINDS: Mapping[str, ComponentKind] = MappingProxyType({**COMPONENT_KINDS, **EXTRA_KINDS})
