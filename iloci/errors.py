"""The exception types users of iloci catch.

Every error iloci raises on bad input derives from :class:`IlociError`, so an
embedding robot stack can catch one type. Messages say what is wrong and what
to do about it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
import difflib
from typing import Any

__all__ = [
    "IlociError",
    "ProgressCallbackWarning",
    "ConfigError",
    "UnknownComponentError",
    "MissingBackendError",
    "PluginError",
    "PluginNotLoadedError",
    "ObserverError",
    "InvalidDemonstrationError",
    "InvalidInputError",
    "UnreachableTargetError",
    "FeedbackError",
    "StaleAnswerError",
    "NotFittedError",
    "NotLoadedError",
    "MemoryFileError",
    "MemoryConfigError",
    "TimeUnitWarning",
    "DataSetWarning",
    "ColumnsWarning",
]


class IlociError(Exception):
    """Base class of every error iloci raises on purpose."""

    def __reduce__(self) -> tuple[Any, ...]:
        # Exception's own reduce calls cls(*args) on unpickling, which fails for
        # subclasses whose __init__ takes other arguments; an error raised in an
        # evaluation worker process then broke the pool instead of reaching the caller.
        return _rebuild_error, (type(self), self.args, dict(self.__dict__))

    def with_context(self, context: str) -> IlociError:
        """A copy of this error, of the same type and attributes, whose message starts
        with ``context`` (e.g. why the caller needed what failed)."""
        exc = _rebuild_error(type(self), (context + str(self),), dict(self.__dict__))
        if isinstance(exc, ImportError):  # whose str() is its msg
            exc.msg = exc.args[0]
        return exc


def _rebuild_error(cls: type[IlociError], args: tuple[Any, ...],
                   state: dict[str, Any]) -> IlociError:
    exc = cls.__new__(cls)
    exc.args = args
    exc.__dict__.update(state)
    return exc


class ConfigError(IlociError, ValueError):
    """A configuration file or mapping is malformed or holds an invalid value.

    Parameters
    ----------
    message : str
        What is wrong and how to fix it.
    source : str, optional
        The file (or ``"<dict>"``) the configuration came from.
    key : str, optional
        Dotted key that is wrong, e.g. ``"learner.k_cutoff"``.
    line : int, optional
        Line number in the TOML file, when known.
    """

    def __init__(self, message: str, *, source: str | None = None,
                 key: str | None = None, line: int | None = None) -> None:
        self.source = source
        self.key = key
        self.line = line
        where = ""
        if source:
            where = source + (f":{line}" if line else "") + ": "
        super().__init__(where + message)


class MemoryConfigError(ConfigError):
    """A config changes a setting that a saved memory's entries depend on.

    Attributes
    ----------
    conflicts : list of str
        One ``"section.key = saved, now new"`` per setting.
    """

    def __init__(self, memory: str, conflicts: Sequence[str], *,
                 source: str | None = None) -> None:
        self.memory = memory
        self.conflicts = list(conflicts)
        super().__init__(
            f"the memory {memory} cannot be used with this config: "
            + "; ".join(self.conflicts)
            + ". Its entries were learned with the memory's settings and would no longer "
            "recognize their own demonstrations. Leave these settings as the memory has "
            "them (or leave out --config to use the memory's own config), or teach a new "
            "memory. The memory file is unchanged.", source=source)


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """Return ``" Did you mean 'x'?"`` for the closest known name, or ``""``."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.5)
    return f" Did you mean {close[0]!r}?" if close else ""


class UnknownComponentError(IlociError, LookupError):
    """A config names a component no installed plugin registers."""

    def __init__(self, kind: str, name: str, known: Sequence[str]) -> None:
        self.kind = kind
        self.name = name
        self.known = sorted(known)
        listed = ", ".join(repr(k) for k in self.known) or "(none installed)"
        super().__init__(
            f"unknown {kind} {name!r}; known {kind} names: {listed}."
            f"{did_you_mean(name, self.known)} Run `iloci plugins` to see every "
            "registered component and whether its back end is installed."
        )


class MissingBackendError(IlociError, ImportError):
    """A registered component's back-end library is not installed."""

    def __init__(self, kind: str, name: str, missing: Sequence[str],
                 install: str) -> None:
        self.kind = kind
        self.name = name
        self.missing = list(missing)
        self.install = install
        super().__init__(
            f"{kind} {name!r} needs {', '.join(self.missing)}, which is not "
            f"installed. Install it with: {install}"
        )


class PluginError(IlociError):
    """A plugin failed to load or implements a hook that does not exist."""


class PluginNotLoadedError(MissingBackendError):
    """A configured component's plugin is installed but was not loaded.

    Blocked (``ILOCI_BLOCK_PLUGINS``), not autoloaded
    (``ILOCI_DISABLE_PLUGIN_AUTOLOAD``) or failed to load: the message says
    which. A :class:`MissingBackendError`, since the back end cannot be
    built, but never worded "not installed".
    """

    def __init__(self, kind: str, name: str, why: str) -> None:
        IlociError.__init__(self, f"{kind} {name!r} is not available: {why}.")
        self.kind = kind
        self.name = name
        self.missing: list[str] = []
        self.install = ""


class ObserverError(PluginError):
    """An observer hook raised while being told about a committed learning step.

    The learning step it observed is complete (memory updated); observers
    run only after that, so a fault never leaves it half done.

    Attributes
    ----------
    hook : str
        The hook, e.g. ``"iloci_on_interaction"``.
    plugin : str
        The plugin whose implementation raised (the first, when several did).
    error : Exception
        What it raised.
    outcome : LearnOutcome
        What the learning step did: the demonstration is learned.
    """

    def __init__(self, hook: str, plugin: str, error: BaseException, outcome: Any,
                 faults: int = 1, context: str = "") -> None:
        self.hook = hook
        self.plugin = plugin
        self.error = error
        self.outcome = outcome
        more = f" ({faults - 1} more observer fault(s) in this step)" if faults > 1 else ""
        demo = getattr(outcome, "demo", "?")
        if context:   # an evaluation: the fold stops, there is nothing to teach again
            super().__init__(
                f"observer hook {hook} of plugin {plugin!r} raised {type(error).__name__}: "
                f"{error} in {context} (at {demo!r}); the evaluation stopped there. Fix or "
                f"block the plugin (ILOCI_BLOCK_PLUGINS={plugin}) and run it again.")
            return
        super().__init__(
            f"observer hook {hook} of plugin {plugin!r} raised {type(error).__name__}: "
            f"{error}{more}. The demonstration {demo!r} was learned (the memory is "
            "updated and every other observer was told); do not teach it again. Fix or "
            f"block the plugin (ILOCI_BLOCK_PLUGINS={plugin}).")


class InvalidInputError(IlociError, ValueError):
    """An array or value passed to iloci has the wrong shape, type or content."""


class InvalidDemonstrationError(InvalidInputError):
    """A demonstration (pen trajectory) cannot be used: NaN, too short, ..."""


class UnreachableTargetError(InvalidInputError):
    """An IK target lies outside the arm's reachable workspace.

    Attributes
    ----------
    index : int
        Index of the first unreachable point in the path.
    point : tuple of float
        Its coordinates (m, torso frame).
    error : float
        Remaining position error (m) after the solver gave up.
    """

    def __init__(self, message: str, *, index: int = -1,
                 point: Sequence[float] = (), error: float = float("nan")) -> None:
        self.index = index
        self.point = tuple(float(p) for p in point)
        self.error = error
        super().__init__(message)


class FeedbackError(IlociError, ValueError):
    """A teacher returned something other than +1 or -1."""


class StaleAnswerError(InvalidInputError):
    """A feedback names an answer that is not waiting for one; nothing changed.

    Every answer the robot gives carries an id (:attr:`Answer.id
    <iloci.concepts.learner.Answer.id>`) and a feedback names the id it
    judges. An id that is not the pending answer's (a duplicate of a
    feedback already taken, a late one for an answer since replaced, one
    for another turn or a turn that is over) is refused with this error;
    the memory and the turn are left as they were, so event-driven stacks
    (buttons, ROS topics, web hooks) that deliver duplicates or late
    messages can drop it.

    Attributes
    ----------
    answer_id : str
        The id the feedback named.
    pending : str or None
        The id of the answer waiting for a feedback (``None``: none is).
    """

    def __init__(self, message: str, *, answer_id: str = "",
                 pending: str | None = None) -> None:
        self.answer_id = answer_id
        self.pending = pending
        super().__init__(message)


class NotFittedError(IlociError, RuntimeError):
    """An operation needs learned state that does not exist yet."""


class NotLoadedError(IlociError, RuntimeError):
    """A component was not built, because the memory was loaded for another purpose.

    ``Agent.load(path, purpose="recognize")`` builds only what recognition
    needs; the clusterer and the teacher stand in as placeholders that
    raise this on use.
    """


class MemoryFileError(IlociError, OSError):
    """A saved memory file is missing, truncated, tampered with or too new."""


class TimeUnitWarning(UserWarning):
    """A demonstration's time stamps look like another unit than seconds (e.g. ms).

    iloci reads time stamps in seconds; only the robot's drawing speed
    depends on them (the default path reading, ``resample = "arc_length"``,
    does not read them at all), so this is a warning, not an error.
    """


class DataSetWarning(UserWarning):
    """A data set is read, but not quite as it lies on disk.

    Files left out (names starting with ``_``, formats that are not
    trajectory files, folders beside a manifest), or names that differ only
    in case or spaces: what the evaluation scores is not everything the
    user put there, so it says so once, before anything is learned.
    """


class ColumnsWarning(UserWarning):
    """A trajectory file's columns may have been read as other columns than they are.

    A CSV file without a header is read by the number of its columns (x, y
    or t, x, y); when what comes out looks like another layout (a y that
    takes only a few values: a pen's pressure), the file is read as it
    says, and this warning names it and the header that would settle it.
    """


class ProgressCallbackWarning(UserWarning):
    """``agent.on_progress`` raised: the report is dropped, the rehearsal goes on.

    A display callback (a progress bar, a ROS topic) that fails must not
    stop learning half-way: the demonstration is learned as it would be
    without the callback.
    """
