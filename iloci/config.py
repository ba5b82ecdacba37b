"""Configuration: TOML -> validated, frozen dataclasses.

Every value has a default; the defaults are the paper's settings. A config
names components (``name = "native-rnnpb"``), never import paths. Each
component section's other keys are validated by that component's own schema
(a light dataclass the plugin registers) before anything heavy is imported.

Example::

    [perceptual_model]
    name = "native-rnnpb"
    hidden = 60
    [clusterer]
    name = "sklearn"
    [learner]
    k_cutoff = 0.5
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
import dataclasses
from dataclasses import dataclass, field
import os
from pathlib import Path
import re
import tomllib
from typing import Any

from iloci._version import __version__, is_newer
from iloci.errors import ConfigError, MissingBackendError, UnknownComponentError, did_you_mean
from iloci.interfaces import COMPONENT_KINDS
from iloci.plugins import get_registry
from iloci.registry import Registry, params_to_dict, validate_dataclass, validate_params
from iloci.sections import (_PLAIN_SECTIONS, DataConfig, EvaluationConfig, LearnerConfig,
                            RobotConfig, SensorimotorConfig)

__all__ = [
    "Config",
    "ComponentConfig",
    "LearnerConfig",
    "SensorimotorConfig",
    "RobotConfig",
    "DataConfig",
    "EvaluationConfig",
    "check_installed",
    "memory_conflicts",
    "load_config",
    "to_toml",
]

#: The component each section names when a config leaves its name out.
DEFAULT_NAMES = {
    # native-rnnpb: its C kernel is the fastest training step measured and
    # gives the same bits on every CPU; it needs numpy only (no torch), so
    # the default config installs in seconds and runs on Python 3.11 to 3.13
    # (benchmarks/results/rnnpb_speed.json, step_ms_by_kernel)
    "perceptual_model": "native-rnnpb",
    "clusterer": "scipy",
    "teacher": "oracle",
    "ik": "pinocchio",
    "simulator": "none",
}


@dataclass(frozen=True)
class ComponentConfig:
    """A component chosen by name plus its validated parameters.

    Attributes
    ----------
    name : str
        Registered name, or ``"none"`` for an optional component left out.
    params : dataclass instance, dict or None
        The component's schema filled from the config section. A plain
        dict of the section's other keys, unvalidated, when the component
        was given to :func:`~iloci.agent.build` as an object (its name was
        not looked up, so there is no schema to check them against).
    """

    name: str
    params: Any = None

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, **params_to_dict(self.params)}




@dataclass(frozen=True)
class Config:
    """A whole iloci configuration. Build one with :func:`load_config`."""

    perceptual_model: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["perceptual_model"]))
    clusterer: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["clusterer"]))
    teacher: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["teacher"]))
    ik: ComponentConfig = field(default_factory=lambda: ComponentConfig(DEFAULT_NAMES["ik"]))
    simulator: ComponentConfig = field(
        default_factory=lambda: ComponentConfig(DEFAULT_NAMES["simulator"]))
    learner: LearnerConfig = field(default_factory=LearnerConfig)
    sensorimotor: SensorimotorConfig = field(default_factory=SensorimotorConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    data: DataConfig = field(default_factory=DataConfig)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)
    #: Where the config came from (a path or ``"<dict>"``).
    source: str = "<defaults>"
    # What load_config resolved the names with, so replace() re-validates the
    # same way (a custom registry, objects the caller supplies); not data.
    _registry: Any = field(default=None, compare=False, repr=False)
    _supplied: frozenset = field(default=frozenset(), compare=False, repr=False)

    @property
    def seed(self) -> int:
        return self.evaluation.seed

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict, every value resolved (TOML-serialisable)."""
        out: dict[str, Any] = {}
        for sec in COMPONENT_KINDS:
            out[sec] = getattr(self, sec).to_dict()
        for sec in _PLAIN_SECTIONS:
            out[sec] = params_to_dict(getattr(self, sec))
        return out

    def replace(self, **changes: Any) -> Config:
        """A copy with some values changed, e.g. ``replace(teacher={"name": "noisy"})``.

        Values are validated like a config file's, with the registry and
        the supplied sections this config was loaded with (see
        :func:`load_config`); a section given as a mapping updates that
        section. The copy keeps :attr:`source`.
        """
        data = self.to_dict()
        for sec, value in changes.items():
            if isinstance(value, Mapping) and isinstance(data.get(sec), dict):
                if sec in COMPONENT_KINDS and "name" in value and \
                        value["name"] != data[sec]["name"]:
                    data[sec] = dict(value)  # another component: its own defaults
                else:
                    data[sec].update(value)
            else:
                data[sec] = value
        named = ConfigData(data)  # errors and the copy still name the file it came from
        named.source = self.source
        return load_config(named, registry=self._registry, supplied=self._supplied)


_LINE_RE = re.compile(r"line (\d+)")


def _read_text(path: Path, what: str) -> str:
    """The text of a TOML file (see :func:`read_toml`)."""
    try:
        raw = path.read_bytes()
        if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
            raise ConfigError(f"{what} is UTF-16 text (it starts with a UTF-16 byte-order "
                              "mark); TOML files are UTF-8: save it as UTF-8.",
                              source=str(path))
        head = raw[:200]
        if len(head) >= 4 and head.count(0) * 3 >= len(head):
            # ASCII in UTF-16 without a mark: every other byte is zero
            raise ConfigError(f"{what} looks like UTF-16 text (every other byte is zero); "
                              "TOML files are UTF-8: save it as UTF-8.", source=str(path))
        if raw.startswith(b"PK\x03\x04"):  # a zip: what an iloci memory (.npz) is
            raise ConfigError(f"{what} {path.name} is a zip file (an iloci memory, .npz?), "
                              "not TOML text: a memory goes to --memory, a config is a "
                              ".toml file (`iloci config show` prints one).", source=str(path))
        # a UTF-8 byte-order mark (what Notepad and PowerShell write) is no content
        text = raw.decode("utf-8-sig")
    except FileNotFoundError:
        raise ConfigError(f"{what} file not found: {path}. Pass an existing TOML "
                          "file" + (", or see `iloci config show` for a full example." if
                                    what == "config" else "."),
                          source=str(path)) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} is not UTF-8 text ({exc.reason} at byte {exc.start}, "
                          f"{exc.object[exc.start:exc.start + 1]!r}); TOML files are UTF-8: "
                          "save it as UTF-8 (from Latin-1 or Windows-1252: `iconv -f cp1252 "
                          f"-t utf-8 {path.name} > NEW.toml`).",
                          source=str(path)) from None
    except IsADirectoryError:
        raise ConfigError(f"{what} path is a directory; pass a TOML file.",
                          source=str(path)) from None
    except OSError as exc:
        raise ConfigError(f"cannot read {what}: {exc.strerror}.", source=str(path)) from None
    if "\r" in text and "\n" not in text:
        raise ConfigError(f"{what}'s lines end with a carriage return only (classic Mac OS "
                          "text); TOML needs line feeds: save it with LF (or CRLF) line ends.",
                          source=str(path))
    return text


def read_toml(path: str | os.PathLike[str], what: str = "config") -> dict[str, Any]:
    """The tables of a TOML file, read the one way every iloci file is read.

    A UTF-8 byte-order mark is skipped; UTF-16, other encodings, a missing
    file, a directory and malformed TOML are each one :class:`ConfigError`
    naming the file (and line), with ``what`` (e.g. ``"sweep spec"``) for
    the kind of file.
    """
    path = Path(path)
    return _parse_toml(_read_text(path, what), path)


#: What a file of another format is called, by its suffix, in the error that it is not TOML.
_NOT_TOML = {".json": "JSON", ".yaml": "YAML", ".yml": "YAML", ".ini": "INI", ".cfg": "INI",
             ".xml": "XML", ".py": "Python"}


def _parse_toml(text: str, path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = _LINE_RE.search(str(exc))
        line = int(m.group(1)) if m else None
        kind = _NOT_TOML.get(path.suffix.lower())
        if kind is not None:
            raise ConfigError(f"this is a {kind} file ({path.name}), and iloci reads TOML "
                              f"([section] then key = value lines); TOML's parser says: {exc}. "
                              "Write the settings as TOML (`iloci config show` prints every "
                              "one in TOML).", source=str(path), line=line) from None
        raise ConfigError(f"malformed TOML: {exc}", source=str(path), line=line) from None
    except RecursionError:
        raise ConfigError("its arrays or tables are nested too deeply to read (an iloci "
                          "config nests two levels: [section] key = value)",
                          source=str(path)) from None


class ConfigData(dict[str, Any]):
    """A config file's tables as :func:`read_config_file` read them; ``source`` is the file.

    :func:`load_config` names it in its errors as it names a file it reads.
    """

    source: str = "<dict>"
    #: The iloci version that wrote the file (its ``# ... written by iloci X``
    #: first line, as ``iloci config show`` writes it), "" when it says none.
    written_by: str = ""


_WRITTEN_BY_RE = re.compile(r"^#.*\bwritten by iloci ([0-9][^\s,;)]*)", re.MULTILINE)


def read_config_file(path: str | os.PathLike[str]) -> ConfigData:
    """A config file's tables, read once (:func:`read_toml`), its robot's relative paths
    made absolute beside the file.

    A relative ``[robot] urdf`` or ``package_dirs`` means a path beside the
    config file, not in the current folder: the config means the same from
    anywhere, and a memory stores the absolute path, so it loads from anywhere.
    Pass the result to :func:`load_config` (or change it first, as ``iloci
    sweep`` does with its base config).
    """
    path = Path(path)
    text = _read_text(path, "config")
    data = ConfigData(_parse_toml(text, path))
    data.source = str(path)
    m = _WRITTEN_BY_RE.search(text[:2000])
    data.written_by = m.group(1) if m else ""
    robot = data.get("robot")
    if isinstance(robot, dict):
        robot = data["robot"] = dict(robot)

        def absolute(p: Any) -> Any:
            if not isinstance(p, str) or not p or p.startswith("package://"):
                return p
            q = Path(p.removeprefix("file://")).expanduser()
            return str(q if q.is_absolute() else (path.parent / q).resolve())

        if "urdf" in robot:
            robot["urdf"] = absolute(robot["urdf"])
        if isinstance(robot.get("package_dirs"), list):
            robot["package_dirs"] = [absolute(d) for d in robot["package_dirs"]]
    return data


def load_config(source: str | os.PathLike[str] | Mapping[str, Any] | Config | None = None,
                *, registry: Registry | None = None,
                supplied: Iterable[str] = ()) -> Config:
    """Load and validate a configuration.

    Parameters
    ----------
    source : path, mapping, Config or None
        A TOML file, a nested mapping of the same shape, an existing
        :class:`Config` (returned as is) or ``None`` for the defaults.
    registry : Registry, optional
        Registry to resolve component names in; by default one is built
        from the installed plugins.
    supplied : iterable of str
        Component sections (``"ik"``, ``"teacher"``, ...) whose component
        the caller supplies as an object, as :func:`~iloci.agent.build`
        does for its overrides. Their name is not looked up (it need not
        be registered, nor its back end installed) and their other keys
        are kept as given, unvalidated. Ignored when ``source`` is already
        a :class:`Config`.

    Returns
    -------
    Config

    Raises
    ------
    ConfigError
        Malformed TOML (with line), unknown key (naming key and file), wrong
        type or out-of-range value.
    UnknownComponentError
        A component name no plugin registers (with "did you mean").
    """
    if isinstance(source, Config):
        return source
    if source is None:
        data: Mapping[str, Any] = {}
        origin = "<defaults>"
    elif isinstance(source, Mapping):
        data = source
        origin = getattr(source, "source", "<dict>")
    elif isinstance(source, (str, os.PathLike)):
        data = read_config_file(source)
        origin = data.source
        if is_newer(data.written_by):
            try:
                return load_config(data, registry=registry, supplied=supplied)
            except (ConfigError, UnknownComponentError) as exc:
                raise ConfigError(
                    f"written by iloci {data.written_by}, this is iloci {__version__}: upgrade "
                    f"iloci (and its plugins) to read it, or remove what this version does not "
                    f"know ({exc})", source=origin) from None
    else:
        raise ConfigError(f"load_config takes a path, a mapping or None, got "
                          f"{type(source).__name__}.")
    supplied = set(supplied)
    bad = supplied - set(COMPONENT_KINDS)
    if bad:
        raise ConfigError(f"supplied names no component section: {sorted(bad)}; component "
                          f"sections are {', '.join(COMPONENT_KINDS)}.")
    if registry is None and not supplied >= set(COMPONENT_KINDS):
        registry = get_registry()

    known = set(COMPONENT_KINDS) | set(_PLAIN_SECTIONS)
    for key, value in data.items():
        if not isinstance(key, str):
            raise ConfigError(f"section names are strings, got {key!r}; valid sections are "
                              f"{', '.join(sorted(known))}.", source=origin)
        if key not in known:
            raise ConfigError(
                f"unknown section or key {key!r}; valid sections are "
                f"{', '.join(sorted(known))}.{did_you_mean(key, known)}",
                source=origin, key=key)
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key!r} must be a table ([{key}]), got {value!r}.",
                              source=origin, key=key)

    kwargs: dict[str, Any] = {"source": origin}
    elsewhere = _keys_of_sections(data, registry, supplied)
    # A typo is reported before a missing back end: it is what the user can fix here.
    missing: MissingBackendError | None = None
    for sec, kind in COMPONENT_KINDS.items():
        values = dict(data.get(sec, {}))
        name = values.pop("name", DEFAULT_NAMES[sec])
        if not isinstance(name, str):
            raise ConfigError(f"{sec}.name must be a string, got {name!r}.",
                              source=origin, key=f"{sec}.name")
        if sec in supplied:  # the caller's object stands in: nothing to look up
            kwargs[sec] = ComponentConfig(name, values or None)
            continue
        assert registry is not None
        if name == "none":
            if not kind.optional:
                raise ConfigError(f"[{sec}] is required; 'none' is not allowed. Known "
                                  f"names: {', '.join(registry.names(sec))}.",
                                  source=origin, key=f"{sec}.name")
            if values:
                raise ConfigError(f"[{sec}] name = 'none' takes no other keys, got "
                                  f"{', '.join(values)}.", source=origin, key=sec)
            kwargs[sec] = ComponentConfig("none", None)
            continue
        try:
            spec = registry.get(sec, name)
        except UnknownComponentError as exc:
            exc.args = (f"{origin}: [{sec}] name: {exc.args[0]}",)
            raise
        except MissingBackendError as exc:
            missing = missing or exc
            continue
        kwargs[sec] = ComponentConfig(name, validate_params(spec, values, source=origin,
                                                            elsewhere=elsewhere))
    for sec, cls in _PLAIN_SECTIONS.items():
        kwargs[sec] = validate_dataclass(cls, dict(data.get(sec, {})), section=sec,
                                         source=origin, elsewhere=elsewhere)
    if missing is not None:
        raise missing
    return Config(**kwargs, _registry=registry, _supplied=frozenset(supplied))


def _keys_of_sections(data: Mapping[str, Any], registry: Any,
                      supplied: set[str]) -> dict[str, set[str]]:
    """Every section's keys: the plain sections' and those of the components ``data``
    names (or the defaults), as far as the registry knows them (for the hint that a key
    belongs in another section)."""
    keys = {sec: {f.name for f in dataclasses.fields(cls)}
            for sec, cls in _PLAIN_SECTIONS.items()}
    for sec in COMPONENT_KINDS:
        keys[sec] = {"name"}
        name = (data.get(sec) or {}).get("name", DEFAULT_NAMES[sec])
        if registry is None or sec in supplied or not isinstance(name, str) or name == "none":
            continue
        try:
            params = registry.get(sec, name).params
        except (UnknownComponentError, MissingBackendError):  # said in its turn below
            continue
        if params is not None:
            keys[sec] |= {f.name for f in dataclasses.fields(params)}
    return keys


#: Sections every setting of which a saved memory's entries depend on.
MEMORY_SECTIONS = ("sensorimotor", "robot")


def memory_conflicts(saved: Mapping[str, Any], config: Config) -> list[str]:
    """Settings of ``config`` that change what a saved memory's entries mean.

    A memory's entries are PB vectors of its network for sequences encoded
    with its settings: every ``[sensorimotor]`` setting (steps, resampling,
    smoothing), every ``[robot]`` setting (the arm and its drawing plane) and
    each component's ``MEMORY_KEYS`` (a class attribute of its parameter
    schema: the RNNPB's sizes and PB range, the IK's null-space pull).
    Changing one would make the memory misread its own demonstrations, so a
    config that does is refused; every other setting
    (teacher, thresholds, epochs, recognition, simulator) may change.

    Parameters
    ----------
    saved : mapping
        The config saved with the memory (:meth:`Config.to_dict` form).
    config : Config
        The config it is about to be used with.

    Returns
    -------
    list of str
        One ``"section.key = saved value, now new value"`` per conflict;
        empty when the memory can be used with ``config``.
    """
    out: list[str] = []
    new = config.to_dict()
    keys: dict[str, tuple[str, ...]] = {}
    for sec in MEMORY_SECTIONS:
        keys[sec] = tuple(f.name for f in dataclasses.fields(getattr(config, sec)))
    for sec in COMPONENT_KINDS:
        params = getattr(config, sec).params
        keys[sec] = tuple(getattr(params, "MEMORY_KEYS", ())) if params is not None else ()
    for sec, names in keys.items():
        section = saved.get(sec)
        old_sec: Mapping[str, Any] = section if isinstance(section, Mapping) else {}
        defaults = params_to_dict(type(getattr(config, sec))()) if sec in MEMORY_SECTIONS \
            else None
        for key in names:
            if key not in new.get(sec, {}):
                continue
            now = new[sec][key]
            if key in old_sec:
                was = old_sec[key]
            elif defaults is not None:
                was = defaults.get(key)
            else:  # a component key the saved config left out: its schema's default
                params = getattr(config, sec).params
                was = params_to_dict(type(params)()).get(key)
            if isinstance(was, list) or isinstance(now, list):
                was, now = list(was or ()), list(now or ())
            if was != now:
                out.append(f"{sec}.{key} = {was!r} in the memory, {now!r} in the config")
    return out


def check_installed(config: Config, registry: Registry | None = None) -> None:
    """Raise unless every configured component's back-end modules can be imported,
    and the ``[robot]`` preset (without ``urdf``) is registered.

    :func:`load_config` checks that each configured name is registered
    (its plugin installed and loaded); this checks what the plugin needs
    (``torch``, ``pinocchio``, ...) without importing it, so ``iloci config
    check`` and ``iloci evaluate`` report a missing library before anything
    runs rather than when the component is built.

    Raises
    ------
    MissingBackendError
        Naming the component, the missing modules and the install command
        (for ``panda``/``ur5`` without ``iloci-robots``: that plugin).
    UnknownComponentError
        No robot preset of that name (the known ones listed).
    PluginNotLoadedError
        The robot's plugin is installed but blocked or not loaded.
    """
    registry = registry or config._registry
    if registry is None:
        registry = get_registry()
    for sec, kind in COMPONENT_KINDS.items():
        name = getattr(config, sec).name
        if name == "none" or sec in config._supplied:
            continue
        spec = registry.get(sec, name)
        missing = spec.missing()
        if missing:
            raise MissingBackendError(kind.label, name, missing,
                                      spec.install or f"pip install {' '.join(missing)}")
    if not config.robot.urdf:  # a preset: registered, by an installed and loaded plugin
        try:
            spec = registry.get("robot", config.robot.name)
        except UnknownComponentError as exc:
            exc.args = (f"{config.source or 'config'}: [robot] name: {exc.args[0]}",)
            raise
        missing = spec.missing()
        if missing:
            raise MissingBackendError("robot", spec.name, missing,
                                      spec.install or f"pip install {' '.join(missing)}")


def to_toml(config: Config) -> str:
    """The resolved config as TOML text (every default written out; tomli-w).

    Raises
    ------
    ConfigError
        A value TOML cannot hold (a component's unvalidated key given an
        object, say).
    """
    import tomli_w

    data = {sec: {k: v for k, v in values.items() if v is not None}
            for sec, values in config.to_dict().items()}
    try:
        body = tomli_w.dumps(data)
    except TypeError as exc:
        raise ConfigError(f"cannot write the config as TOML: {exc}", source=config.source) \
            from None
    return (f"# iloci configuration (resolved from {config.source}), written by iloci "
            f"{__version__}\n\n{body}")
