"""Validation of a component's or a section's settings against its dataclass schema.

Types as a TOML user writes them (a list of numbers, a table), unknown keys
with did-you-mean, finite numbers, 64-bit integers, then the declared
constraints (:func:`iloci.constraints.violations`) and the schema's own
``validate()``. Used by the registry (a component's section) and the config.
"""

from __future__ import annotations

from collections.abc import Mapping
import dataclasses
import math
import types
import typing
from typing import Any, Union

from iloci.constraints import violations
from iloci.errors import ConfigError, PluginError, did_you_mean

__all__ = ["params_to_dict", "schema_problems", "validate_dataclass"]


def _type_ok(value: Any, tp: Any) -> tuple[bool, Any]:
    """Check ``value`` against a simple annotation; return (ok, coerced).

    A numpy scalar or array (a value computed in numpy, from embedding code)
    is read as the Python value it holds (``.item()``, ``.tolist()``).
    """
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):
        value = value.tolist()
    if tp is Any:
        return True, value
    origin = typing.get_origin(tp)
    if origin is typing.Literal:   # the value must be one of them (a bool is not 1)
        return any(value == a and type(value) is type(a) for a in typing.get_args(tp)), value
    if origin in (Union, types.UnionType):
        for arg in typing.get_args(tp):
            ok, v = _type_ok(value, arg)
            if ok:
                return True, v
        return False, value
    if tp is type(None):
        return value is None, value
    if tp is bool:
        return isinstance(value, bool), value
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool), value
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return True, float(value)
        return False, value
    if tp is str:
        return isinstance(value, str), value
    if origin in (tuple, list) or tp in (tuple, list):
        if not isinstance(value, (list, tuple)):
            return False, value
        args = typing.get_args(tp)
        if args and not (len(args) == 2 and args[1] is Ellipsis) and origin is tuple:
            if len(args) != len(value):
                return False, value
            out = []
            for v, a in zip(value, args):
                ok, c = _type_ok(v, a)
                if not ok:
                    return False, value
                out.append(c)
            return True, tuple(out)
        elem = args[0] if args else Any
        out = []
        for v in value:
            ok, c = _type_ok(v, elem)
            if not ok:
                return False, value
            out.append(c)
        return True, tuple(out)
    if isinstance(tp, type):
        return isinstance(value, tp), value
    return True, value


_PLURAL = {bool: "true/false values", int: "integers", float: "numbers", str: "strings"}
_SINGULAR = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}


def _type_name(tp: Any) -> str:
    """A type as a TOML user reads it: ``tuple[float, ...]`` -> "a list of numbers"."""
    if tp in _SINGULAR:
        return _SINGULAR[tp]
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin is typing.Union or isinstance(tp, types.UnionType):
        return " or ".join(_type_name(a) for a in args if a is not type(None))
    if origin in (tuple, list) or tp in (tuple, list):
        if args and not (len(args) == 2 and args[1] is Ellipsis) and origin is tuple:
            if len(set(args)) == 1 and args[0] in _PLURAL:
                return f"a list of {len(args)} {_PLURAL[args[0]]}"
            return f"a list of {len(args)} values"
        if args and args[0] in _PLURAL:
            return f"a list of {_PLURAL[args[0]]}"
        return "a list"
    if origin is dict or tp is dict:
        return "a table"
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _scalar(value: Any) -> type | None:
    """The TOML scalar type of ``value`` (bool before int: a bool is an int), or None."""
    return next((tp for tp in _SINGULAR if isinstance(value, tp)), None)


def _value_kind(value: Any) -> str:
    """What a TOML value is, in :func:`_type_name`'s words."""
    tp = _scalar(value)
    if tp is not None:
        return _SINGULAR[tp]
    if isinstance(value, (list, tuple)):
        kinds = sorted({_PLURAL.get(_scalar(v) or object, "other values") for v in value})
        return "a list" + (f" of {' and '.join(kinds)}" if kinds else ", empty")
    if isinstance(value, Mapping):
        return "a table"
    return type(value).__name__


def misplaced(section: str, key: str, value: Any,
              elsewhere: Mapping[str, Any] | None) -> str:
    """A hint for an unknown ``section.key`` that belongs in another section, or ``""``.

    ``elsewhere`` maps the other sections to their keys: a key of one of them
    (``k_cutoff`` under ``[evaluation]``) is named with its section; a
    section's name used as a dotted key (``learner.k_cutoff = 0.4`` under
    ``[perceptual_model]``, which TOML reads as ``perceptual_model.learner``)
    is explained.
    """
    if not elsewhere:
        return ""
    if key in elsewhere and isinstance(value, Mapping):
        inner = next(iter(value), "KEY")
        return (f" {key}.{inner} under [{section}] is read as {section}.{key}.{inner} (a "
                f"dotted key stays in its table); write {inner} under [{key}] instead.")
    homes = [sec for sec, keys in elsewhere.items() if sec != section and key in keys]
    if homes:
        return (f" {key!r} is a key of {' and '.join(f'[{h}]' for h in homes)}: move it "
                "there.")
    return ""


def validate_dataclass(cls: type, values: Mapping[str, Any], *, section: str,
                       source: str | None = None,
                       elsewhere: Mapping[str, Any] | None = None) -> Any:
    """Build dataclass ``cls`` from ``values``, checking keys and types.

    Unknown keys and wrongly typed values raise :class:`ConfigError` naming
    the key (``section.key``) and the source; an unknown key that another
    section of ``elsewhere`` (section -> its keys) has is pointed there
    (:func:`misplaced`). After construction the instance's ``validate()``
    method, when it has one, may raise ``ValueError`` for out-of-range
    values; that becomes a ConfigError too.
    """
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for key, value in values.items():
        if not isinstance(key, str):
            raise ConfigError(f"keys in [{section}] are strings, got {key!r}; valid keys are "
                              f"{', '.join(sorted(fields)) or '(none)'}.", source=source)
        if key not in fields:
            hint = misplaced(section, key, value, elsewhere) or did_you_mean(key, fields)
            raise ConfigError(
                f"unknown key {section + '.' + key!r}; valid keys in [{section}] are "
                f"{', '.join(sorted(fields)) or '(none)'}.{hint}",
                source=source, key=f"{section}.{key}")
        ok, coerced = _type_ok(value, hints.get(key, Any))
        if not ok:
            raise ConfigError(
                f"{section}.{key} must be {_type_name(hints.get(key))}, got "
                f"{value!r} ({_value_kind(value)}).", source=source, key=f"{section}.{key}")
        if not _all_finite(coerced):
            raise ConfigError(
                f"{section}.{key} must be a finite number, got {value!r}: TOML spells "
                "nan and inf, but no setting of iloci means either.",
                source=source, key=f"{section}.{key}")
        if isinstance(coerced, int) and not -2**63 <= coerced < 2**63:
            raise ConfigError(f"{section}.{key} is out of range: {value!r} does not fit in "
                              "a 64-bit integer.", source=source, key=f"{section}.{key}")
        kwargs[key] = coerced
    needed = [name for name, f in fields.items() if name not in kwargs
              and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    if needed:  # a setting without a default (hooks.md asks for defaults): the user's to give
        raise ConfigError(f"[{section}] needs {', '.join(needed)}: this {section} has no "
                          f"default for {'it' if len(needed) == 1 else 'them'}; set "
                          f"{', '.join(f'{n} = ...' for n in needed)} under [{section}].",
                          source=source, key=f"{section}.{needed[0]}")
    try:
        obj = cls(**kwargs)
    except (ValueError, TypeError, OverflowError) as exc:
        raise ConfigError(f"[{section}]: {exc}", source=source, key=section) from None
    for name, message in violations(obj)[:1]:  # the declared constraints: one validator
        raise ConfigError(f"[{section}]: {message}", source=source, key=f"{section}.{name}")
    try:
        check = getattr(obj, "validate", None)  # rules that tie fields together
        if callable(check):
            check()
    except (ValueError, OverflowError) as exc:
        raise ConfigError(f"[{section}]: {exc}", source=source, key=section) from None
    except Exception as exc:
        # validate() reports a bad value by ValueError (hooks.md); anything else is a
        # fault of its code, not of the config: said as the plugin's
        raise PluginError(
            f"[{section}]: {cls.__module__}.{cls.__qualname__}.validate() failed with "
            f"{type(exc).__name__}: {exc}. That is a fault of the code that defines "
            f"[{section}]'s settings (module {cls.__module__}), not of the config: report "
            "it to its authors, or leave the plugin out with ILOCI_BLOCK_PLUGINS "
            "(docs/hooks.md).") from exc
    return obj


def _tomlable(tp: Any) -> bool:
    """Whether a TOML file can give a value of annotation ``tp`` (and a memory's JSON
    header hold it): str, int, float, bool, Any, a Literal of those, Optional, lists and
    tuples of those, a table of str keys."""
    if tp is Any or tp in _SINGULAR or tp is type(None):
        return True
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Literal:
        return all(_scalar(a) is not None for a in args)
    if origin in (Union, types.UnionType):
        return all(_tomlable(a) for a in args)
    if origin in (tuple, list) or tp in (tuple, list):
        return all(a is Ellipsis or _tomlable(a) for a in args)
    if origin is dict or tp is dict:
        return not args or (args[0] is str and _tomlable(args[1]))
    return False


def schema_problems(cls: type) -> list[str]:
    """What is wrong with a settings dataclass as a schema of TOML keys, one line each.

    Every field a config can set must have a type TOML can give (a
    ``pathlib.Path`` cannot: the config can never set it, and its default
    cannot be written to ``metrics.json`` or a memory's header, which failed
    at the end of a run), and a default of that type, when it has one (a
    ``float`` field defaulting to ``"0.5"`` reached the component unchecked).
    """
    try:
        hints = typing.get_type_hints(cls)
    except Exception as exc:  # noqa: BLE001  (a name the annotations use is not importable)
        return [f"its annotations cannot be read ({type(exc).__name__}: {exc})"]
    problems = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        tp = hints.get(f.name, Any)
        if not _tomlable(tp):
            problems.append(f"{f.name}: {_type_name(tp)} is not a type a TOML config can "
                            "give (str, int, float, bool, a Literal of them, lists and "
                            "tables of them; a path is a str)")
            continue
        default = (f.default if f.default is not dataclasses.MISSING else
                   f.default_factory() if f.default_factory is not dataclasses.MISSING
                   else dataclasses.MISSING)
        if default is not dataclasses.MISSING and not _type_ok(default, tp)[0]:
            problems.append(f"{f.name}: the default {default!r} is not {_type_name(tp)}")
    return problems


def _all_finite(value: Any) -> bool:
    """False when ``value`` is, or holds, a float nan or inf."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, (list, tuple)):
        return all(_all_finite(v) for v in value)
    return True


def params_to_dict(params: Any) -> dict[str, Any]:
    """A params dataclass (or mapping) as a plain dict (tuples kept as lists for TOML)."""
    if params is None:
        return {}
    if isinstance(params, Mapping):
        return {k: list(v) if isinstance(v, tuple) else v for k, v in params.items()}
    out = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out

