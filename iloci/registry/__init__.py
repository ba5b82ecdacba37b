"""Registry of components: (kind, name) -> lazy factory.

A plugin registers a component by *name* with a factory given as a
``"module:attribute"`` string (imported only when the component is built) or
a callable, an optional parameter schema (a dataclass with a default for
every field, defined in a light module), the importable modules it needs and
the pip command that installs them. Nothing heavy is imported until
:meth:`Registry.build`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
import dataclasses
from dataclasses import dataclass
import importlib
import importlib.util
import inspect
from typing import Any

from iloci.errors import (ConfigError, IlociError, InvalidInputError, MissingBackendError,
                          PluginError, PluginNotLoadedError, UnknownComponentError, did_you_mean)
from iloci.interfaces import ALL_KINDS, COMPONENT_KINDS, unmet_members
from iloci.registry.params import (misplaced, params_to_dict, schema_problems,
                                   validate_dataclass)

__all__ = ["ComponentSpec", "Registry", "KindRegistry", "params_to_dict", "validate_dataclass",
           "validate_params"]

#: First-party components and the plugin distribution that provides each, so
#: a config naming one that is not installed gets the install command rather
#: than "unknown name". The distributions live under ``plugins/`` in iloci's
#: source tree.
FIRST_PARTY = {
    ("perceptual_model", "native-rnnpb"): "iloci-native",
    ("perceptual_model", "torch-rnnpb"): "iloci-torch",
    ("perceptual_model", "jax-rnnpb"): "iloci-jax",
    ("clusterer", "scipy"): "iloci-scipy",
    ("clusterer", "sklearn"): "iloci-sklearn",
    ("ik", "pinocchio"): "iloci-pinocchio",
    ("simulator", "pybullet"): "iloci-pybullet",
    ("simulator", "mujoco"): "iloci-mujoco",
    ("executor", "ray"): "iloci-ray",
    ("robot", "panda"): "iloci-robots",
    ("robot", "ur5"): "iloci-robots",
}


def _label(kind: str) -> str:
    k = ALL_KINDS.get(kind)
    return k.label if k is not None else kind


def _check_kind(kind: str) -> None:
    if kind not in ALL_KINDS:
        raise InvalidInputError(f"unknown component kind {kind!r}; kinds are "
                                f"{', '.join(ALL_KINDS)}.{did_you_mean(str(kind), ALL_KINDS)}")


def install_command(distribution: str) -> str:
    """pip command installing a first-party plugin from an iloci checkout."""
    return f"pip install ./plugins/{distribution}  (from a checkout of iloci)"


@dataclass(frozen=True)
class ComponentSpec:
    """How to build one named component.

    Attributes
    ----------
    kind : str
        One of :data:`iloci.interfaces.ALL_KINDS` (the components', ``executor``, ``robot``).
    name : str
        The name a config uses.
    factory : str or callable
        ``"package.module:Class"`` (imported lazily) or a callable. It is
        called with the fields of ``params`` as keyword arguments, plus
        ``seed=`` when it accepts one.
    params : type or None
        A dataclass whose fields (all with defaults) are the component's
        configuration keys. ``None``: the component takes no parameters.
    requires : tuple of str
        Top-level modules that must be importable (e.g. ``("torch",)``).
    install : str
        Command that installs what is missing.
    summary : str
        One line for ``iloci plugins``.
    plugin : str
        Name of the plugin that registered it.
    distribution, version : str or None
        The distribution that ships the plugin.
    describe : str
        ``"module:function"`` returning one line on how the component runs
        on this machine (e.g. which compute kernel), for ``iloci plugins``;
        called only when the component is available. Empty: nothing to say.
    facts : tuple of (str, value)
        What the registration stated for its kind's
        :attr:`~iloci.interfaces.ComponentKind.facts` (a robot's ``joints``
        and ``plane``); read one with :meth:`fact`.
    """

    kind: str
    name: str
    factory: str | Callable[..., Any]
    params: type | None = None
    requires: tuple[str, ...] = ()
    install: str = ""
    summary: str = ""
    plugin: str = ""
    distribution: str | None = None
    version: str | None = None
    describe: str = ""
    facts: tuple[tuple[str, Any], ...] = ()

    def fact(self, name: str) -> Any:
        """The value the registration gave for fact ``name`` (KeyError: none)."""
        return dict(self.facts)[name]

    def missing(self) -> list[str]:
        """Modules in :attr:`requires` that cannot be imported."""
        out = []
        for mod in self.requires:
            try:
                found = importlib.util.find_spec(mod) is not None
            except (ImportError, ValueError):
                found = False
            if not found:
                out.append(mod)
        return out

    @property
    def available(self) -> bool:
        return not self.missing()

    def default_params(self) -> Any:
        return self.params() if self.params is not None else None

    def description(self) -> str:
        """What :attr:`describe` says now ("" without one); its failure, as text.

        Never raises: ``iloci plugins`` must list every component even when
        one plugin's probe is broken.
        """
        if not self.describe or not self.available:
            return ""
        module, _, attr = self.describe.partition(":")
        try:
            return str(getattr(importlib.import_module(module), attr)())
        except Exception as exc:  # noqa: BLE001 - a third-party probe may fail any way
            return f"could not tell ({type(exc).__name__}: {exc})"


class Registry:
    """All registered components, by kind and name."""

    def __init__(self) -> None:
        self._specs: dict[str, dict[str, ComponentSpec]] = {k: {} for k in ALL_KINDS}
        #: Installed plugins that were not loaded (blocked, not autoloaded,
        #: failed): :class:`~iloci.plugins.PluginInfo` each, set by
        #: :func:`~iloci.plugins.get_registry`, so a config naming one of
        #: their components is told why it is missing.
        self.unloaded: list[Any] = []
        #: Names two installed plugins both register: (kind, name) -> their specs. Neither
        #: is used; asking for the name is an error naming both (:meth:`get`).
        self.ambiguous: dict[tuple[str, str], list[ComponentSpec]] = {}

    def remove_plugin(self, plugin: str) -> None:
        """Forget every component registered by ``plugin``."""
        for specs in self._specs.values():
            for name in [n for n, s in specs.items() if s.plugin == plugin]:
                del specs[name]
        for key, claims in list(self.ambiguous.items()):
            left = [c for c in claims if c.plugin != plugin]
            if len(left) == 1:            # the one claimant left has the name to itself
                del self.ambiguous[key]
                self._specs[key[0]][key[1]] = left[0]
            elif len(left) < len(claims):
                self.ambiguous[key] = left

    def add(self, kind: str, name: str, factory: str | Callable[..., Any], *,
            params: type | None = None, requires: Iterable[str] = (),
            install: str = "", summary: str = "", plugin: str = "",
            distribution: str | None = None, version: str | None = None,
            describe: str = "", **facts: Any) -> ComponentSpec:
        """Register a component. See :class:`ComponentSpec` for the arguments;
        ``facts`` are those the kind requires (:attr:`ComponentKind.facts`)."""
        if kind not in self._specs:
            raise PluginError(f"plugin {plugin!r} registers unknown kind {kind!r}; "
                              f"kinds are {', '.join(ALL_KINDS)}.")
        if not isinstance(name, str) or not name or name == "none":
            raise PluginError(f"plugin {plugin!r} registers an invalid {kind} "
                              f"name {name!r} (non-empty string, not 'none').")
        if isinstance(factory, str) and ":" not in factory:
            raise PluginError(f"plugin {plugin!r}: factory of {kind} {name!r} must be "
                              f"'module:attribute', got {factory!r}.")
        if params is not None and not dataclasses.is_dataclass(params):
            raise PluginError(f"plugin {plugin!r}: params of {kind} {name!r} must be "
                              "a dataclass type.")
        if params is not None:
            problems = schema_problems(params)
            if problems:
                raise PluginError(
                    f"plugin {plugin!r}: the settings of {_label(kind)} {name!r} "
                    f"({getattr(params, '__qualname__', params)}) cannot be a [{kind}] "
                    "section: " + "; ".join(problems) + ".")
        old = self._specs[kind].get(name)
        claims = self.ambiguous.get((kind, name))
        if old is not None and old.plugin == plugin:
            raise PluginError(f"{_who(plugin, distribution)} registers {_label(kind)} {name!r} "
                              "twice: register each name once.")
        installed = distribution not in (None, "iloci")
        if claims is None and old is not None and not (
                installed and old.distribution not in (None, "iloci")):
            # a built-in's name taken, or a collision among plugin objects the caller
            # passed (their code): refused now
            raise PluginError(
                f"{_label(kind)} {name!r} is registered twice: by "
                f"{_who(old.plugin, old.distribution)} and by {_who(plugin, distribution)}. "
                "Uninstall one, or block one with ILOCI_BLOCK_PLUGINS."
            )
        if describe and ":" not in describe:
            raise PluginError(f"plugin {plugin!r}: describe of {kind} {name!r} must be "
                              f"'module:function', got {describe!r}.")
        needed = ALL_KINDS[kind].facts
        if set(facts) != set(needed) or not all(
                isinstance(v, (str, int, float)) for v in facts.values()):
            raise PluginError(
                f"plugin {plugin!r}: {_label(kind)} {name!r} must state "
                f"{', '.join(needed) or 'no facts'} (keyword arguments of registry.add, a "
                f"string or a number each), got {facts or 'none'}.")
        spec = ComponentSpec(kind, name, factory, params, tuple(requires),
                             install or "", summary, plugin, distribution, version, describe,
                             tuple((k, facts[k]) for k in needed))
        if claims is not None or old is not None:
            # two installed plugins claim one name: iloci does not pick one by the
            # order they load in (the other's component would run under that name)
            earlier = claims if claims is not None else [old] if old is not None else []
            self.ambiguous[(kind, name)] = [*earlier, spec]
            self._specs[kind].pop(name, None)
            return spec
        self._specs[kind][name] = spec
        return spec

    def view(self, kind: str, *, plugin: str = "", distribution: str | None = None,
             version: str | None = None) -> KindRegistry:
        return KindRegistry(self, kind, plugin, distribution, version)

    def names(self, kind: str) -> list[str]:
        """Registered names of ``kind``, sorted."""
        _check_kind(kind)
        return sorted(self._specs[kind])

    def specs(self, kind: str | None = None) -> list[ComponentSpec]:
        """The specs of ``kind``; without one, of every component kind (not executors, robots)."""
        if kind is not None:
            _check_kind(kind)
        kinds = tuple(COMPONENT_KINDS) if kind is None else (kind,)
        return [self._specs[k][n] for k in kinds for n in sorted(self._specs[k])]

    def get(self, kind: str, name: str) -> ComponentSpec:
        """The spec of ``name``; :class:`UnknownComponentError` if none, :class:`PluginError`
        if two installed plugins register it (:attr:`ambiguous`)."""
        _check_kind(kind)
        try:
            return self._specs[kind][name]
        except KeyError:
            pass
        claims = self.ambiguous.get((kind, name))
        if claims:
            raise PluginError(ambiguity(kind, name, claims))
        dist = FIRST_PARTY.get((kind, name))
        if dist is not None:
            for info in self.unloaded:
                if info.distribution == dist:
                    raise PluginNotLoadedError(_label(kind), name, info.why_unloaded)
            raise MissingBackendError(_label(kind), name, [dist], install_command(dist))
        exc = UnknownComponentError(_label(kind), name,
                                    list(self._specs.get(kind, {})))
        if self.unloaded:
            exc.args = (exc.args[0] + " Installed plugins that were not loaded: "
                        + "; ".join(i.why_unloaded for i in self.unloaded) + ".",)
        raise exc

    def __contains__(self, item: tuple[str, str]) -> bool:
        kind, name = item
        return name in self._specs.get(kind, {})

    def load_factory(self, spec: ComponentSpec) -> Callable[..., Any]:
        """Import the factory of ``spec`` (the heavy import happens here)."""
        missing = spec.missing()
        if missing:
            raise MissingBackendError(_label(spec.kind), spec.name, missing,
                                      spec.install or f"pip install {' '.join(missing)}")
        if callable(spec.factory):
            return spec.factory
        mod_name, _, attr = spec.factory.partition(":")
        try:
            module = importlib.import_module(mod_name)
        except ImportError as exc:
            missing_mod = getattr(exc, "name", None) or mod_name
            if not _first_party(spec) and not spec.install and \
                    (mod_name + ".").startswith(missing_mod + "."):
                # the plugin names a module of its own that is not there: its bug
                raise PluginError(
                    f"{_label(spec.kind)} {spec.name!r} of plugin {spec.plugin!r} "
                    f"(distribution {spec.distribution or 'none'}): its factory "
                    f"{spec.factory!r} names module {mod_name}, which cannot be imported "
                    f"({exc}). Fix or reinstall the plugin, or block it with "
                    f"ILOCI_BLOCK_PLUGINS={spec.plugin}.") from exc
            raise MissingBackendError(
                _label(spec.kind), spec.name, [missing_mod],
                spec.install or f"pip install {missing_mod}") from exc
        try:
            obj: Any = module
            for part in attr.split("."):
                obj = getattr(obj, part)
        except AttributeError:
            raise PluginError(f"{_label(spec.kind)} {spec.name!r}: {spec.factory!r} "
                              f"does not exist (registered by plugin {spec.plugin!r}).") from None
        return obj

    def build(self, kind: str, name: str, params: Any = None, *, seed: int | None = None,
              **context: Any) -> Any:
        """Construct component ``name`` of ``kind``.

        Parameters
        ----------
        params : dataclass instance, mapping or None
            Validated parameters (a mapping is validated here).
        seed : int, optional
            Passed when the factory accepts ``seed``.
        **context
            Extra keyword arguments passed when the factory accepts them.
        """
        spec = self.get(kind, name)
        if params is None or isinstance(params, Mapping):
            params = validate_params(spec, dict(params or {}))
        factory = self.load_factory(spec)
        kwargs: dict[str, Any] = {}
        if params is not None:
            kwargs.update({f.name: getattr(params, f.name)
                           for f in dataclasses.fields(params)})
        extra = dict(context)
        if seed is not None:
            extra["seed"] = seed
        if extra:
            try:
                sig = inspect.signature(factory)
                takes_all = any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values())
                accepted = set(sig.parameters)
            except (TypeError, ValueError):
                takes_all, accepted = True, set()
            kwargs.update({k: v for k, v in extra.items() if takes_all or k in accepted})
        if _first_party(spec):
            return check_built(spec, factory(**kwargs))
        try:
            built = factory(**kwargs)
        except IlociError:
            raise
        except Exception as exc:  # a third-party factory's own failure: name who
            raise PluginError(
                f"{_label(spec.kind)} {spec.name!r} of plugin {spec.plugin!r} (distribution "
                f"{spec.distribution or 'none'}): its factory {_factory_name(spec.factory)} "
                f"raised {type(exc).__name__}: {exc}. Fix or update the plugin, or block it "
                f"with ILOCI_BLOCK_PLUGINS={spec.plugin}.") from exc
        return check_built(spec, built)


def _who(plugin: str, distribution: str | None) -> str:
    return f"plugin {plugin!r}" + (f" (distribution {distribution})" if distribution else "")


def ambiguity(kind: str, name: str, claims: Iterable[ComponentSpec]) -> str:
    """The message for a name several installed plugins register (:attr:`Registry.ambiguous`)."""
    claims = list(claims)
    return (f"{_label(kind)} {name!r} is registered by {len(claims)} installed plugins: "
            + " and ".join(_who(c.plugin, c.distribution) for c in claims)
            + "; iloci does not guess which one is meant, so neither is used under that "
            "name. Uninstall one, or block one with ILOCI_BLOCK_PLUGINS="
            + claims[-1].plugin + ".")


def _first_party(spec: ComponentSpec) -> bool:
    """Whether iloci or one of its own plugin distributions registered ``spec``."""
    return spec.distribution in (None, "iloci") or \
        spec.distribution in FIRST_PARTY.values()


def check_built(spec: ComponentSpec, obj: Any) -> Any:
    """``obj``, what ``spec``'s factory returned, if it is a component of ``spec.kind``.

    Raises
    ------
    PluginError
        It lacks a member of the kind's protocol (or is None, a class, ...):
        naming the plugin, its distribution, the registration hook and the
        factory, not an AttributeError when the member is first used.
    """
    kind = ALL_KINDS[spec.kind]
    unmet = ["(it is a class, not an instance)"] if isinstance(obj, type) else \
        unmet_members(obj, kind.protocol)
    if unmet:
        raise PluginError(
            f"{kind.label} {spec.name!r} of plugin {spec.plugin or '?'!r} (distribution "
            f"{spec.distribution or 'none'}), registered through {kind.hook}: its factory "
            f"{_factory_name(spec.factory)} returned {type(obj).__name__} {_short(obj)}, which "
            f"is not {kind.label_article}: it lacks {', '.join(unmet)} (see "
            f"iloci.interfaces.{kind.protocol.__name__}). Fix the plugin, or block it with "
            f"ILOCI_BLOCK_PLUGINS={spec.plugin}.")
    if spec.kind == "robot":
        _check_robot_facts(spec, obj)
    return obj


def _check_robot_facts(spec: ComponentSpec, robot: Any) -> None:
    """A robot preset's registration states its joints and plane (``iloci robots`` lists
    them before anything is built); refuse a robot that is not what it was said to be."""
    said, joints = spec.fact("joints"), tuple(robot.joint_names)
    faults = []
    if isinstance(said, int) and said != len(joints):
        faults.append(f"it was registered with joints={said}, but the robot its factory "
                      f"builds moves {len(joints)} ({', '.join(joints)})")
    method = (getattr(robot, "plane_report", None) or {}).get("method")
    if spec.fact("plane") == "given" and method == "placeholder":
        faults.append('it was registered with plane="given", but the robot comes with a '
                      'placeholder plane (register it with plane="auto" to have it placed)')
    if faults:
        raise PluginError(
            f"robot {spec.name!r} of plugin {spec.plugin or '?'!r} (distribution "
            f"{spec.distribution or 'none'}): {'; '.join(faults)}. Fix the registration in "
            f"the plugin's iloci_register_robots, or block it with "
            f"ILOCI_BLOCK_PLUGINS={spec.plugin}.")


def _factory_name(factory: Any) -> str:
    if isinstance(factory, str):
        return factory
    return getattr(factory, "__qualname__", None) or repr(factory)


def _short(obj: Any) -> str:
    text = repr(obj)
    return text if len(text) <= 60 else text[:57] + "..."


class KindRegistry:
    """The view of a :class:`Registry` that a registration hook receives.

    Bound to one kind and to the plugin calling it, so a plugin writes
    ``registry.add("name", "pkg.mod:Class", params=Params, requires=("lib",),
    install="pip install iloci-x")``.
    """

    def __init__(self, registry: Registry, kind: str, plugin: str,
                 distribution: str | None, version: str | None) -> None:
        self._registry = registry
        self.kind = kind
        self._plugin = plugin
        self._distribution = distribution
        self._version = version

    def add(self, name: str, factory: str | Callable[..., Any], *,
            params: type | None = None, requires: Iterable[str] = (),
            install: str = "", summary: str = "", describe: str = "",
            **facts: Any) -> ComponentSpec:
        """Register component ``name`` of this kind (see :class:`ComponentSpec`);
        ``facts``: those the kind requires (a robot's ``joints=J, plane="given"``)."""
        return self._registry.add(self.kind, name, factory, params=params,
                                  requires=requires, install=install, summary=summary,
                                  plugin=self._plugin, distribution=self._distribution,
                                  version=self._version, describe=describe, **facts)

    def names(self) -> list[str]:
        return self._registry.names(self.kind)


def validate_params(spec: ComponentSpec, values: Mapping[str, Any], *,
                    source: str | None = None,
                    elsewhere: Mapping[str, Any] | None = None) -> Any:
    """Validate a component's config keys against its schema (no heavy import).

    ``elsewhere``: the other sections' keys, to point a misplaced key to its
    section (:func:`~iloci.registry.params.misplaced`).
    """
    section = spec.kind
    if spec.params is None:
        if values:
            key = next(iter(values))
            raise ConfigError(
                f"unknown key {section + '.' + key!r}: {_label(spec.kind)} "
                f"{spec.name!r} takes no parameters."
                f"{misplaced(section, key, values[key], elsewhere)}",
                source=source, key=f"{section}.{key}")
        return None
    return validate_dataclass(spec.params, values, section=section, source=source,
                              elsewhere=elsewhere)
