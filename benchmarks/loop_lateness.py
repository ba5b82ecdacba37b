"""A 100 Hz control loop's lateness: how late each tick wakes (ms), as a robot's loop runs.

Shared by ``benchmarks/control_loop.py`` (the loop in a thread) and
``benchmarks/serve.py`` (the loop as an asyncio task beside the server's
learning steps). Tick ``k`` is due at ``t0 + k / HZ``; the loop sleeps until
then and records how late it woke; a tick more than :data:`SKIP_AFTER_S`
late skips the ticks it missed (a real control loop does not run them all
at once afterwards), so one long stall is one late tick, not a burst.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
import threading
import time

#: The loop's rate (ticks per second).
HZ = 100
#: A tick this late (s) skips the ticks it missed.
SKIP_AFTER_S = 0.01
#: Summary names -> percentile (``max`` and ``n`` are always given).
PERCENTILES = {"p50": 50, "median": 50, "p90": 90, "p99": 99}


class Ticks:
    """The schedule of one loop started at ``t0`` (s) and the lateness of each tick.

    Attributes
    ----------
    late : list of (float, float)
        Per tick: the time it woke (s, the loop's clock) and its lateness (ms).
    """

    def __init__(self, t0: float, hz: int = HZ) -> None:
        self.t0 = t0
        self.hz = hz
        self.k = 0
        self.late: list[tuple[float, float]] = []

    def due(self) -> float:
        """The next tick's deadline (s)."""
        self.k += 1
        return self.t0 + self.k / self.hz

    def woke(self, now: float, deadline: float) -> None:
        """Record a tick due at ``deadline`` that woke at ``now``; skip missed ticks."""
        self.late.append((now, (now - deadline) * 1000))
        if now - deadline > SKIP_AFTER_S:
            self.k = int((now - self.t0) * self.hz)

    def lateness_ms(self) -> list[float]:
        """Each tick's lateness (ms), in order."""
        return [late for _, late in self.late]


def run_in_thread(stop: threading.Event, ticks_out: list[tuple[float, float]],
                  clock: Callable[[], float] = time.perf_counter) -> None:
    """The loop in the calling thread until ``stop`` is set; ``(time, lateness ms)`` appended."""
    ticks = Ticks(clock())
    ticks.late = ticks_out
    while not stop.is_set():
        deadline = ticks.due()
        wait = deadline - clock()
        if wait > 0:
            time.sleep(wait)
        ticks.woke(clock(), deadline)


async def run_as_task(stop: asyncio.Event, late_ms: list[float]) -> None:
    """The loop as an asyncio task until ``stop`` is set; each lateness (ms) appended."""
    loop = asyncio.get_running_loop()
    ticks = Ticks(loop.time())
    while not stop.is_set():
        deadline = ticks.due()
        await asyncio.sleep(max(0.0, deadline - loop.time()))
        now = loop.time()
        ticks.woke(now, deadline)
        late_ms.append(ticks.late[-1][1])


def summary(values_ms: list[float], *names: str) -> dict:
    """``{"n", <names>..., "max"}`` of the lateness values (ms, 2 decimals); ``{"n": 0}`` if none.

    ``names`` are keys of :data:`PERCENTILES` (``"p50"``, ``"median"``, ``"p90"``, ``"p99"``).
    """
    import numpy as np  # not before the loop runs: control_loop.py times iloci's import
    a = np.asarray(values_ms, dtype=np.float64)
    if a.size == 0:
        return {"n": 0}
    out: dict = {"n": int(a.size)}
    for name in names:
        out[name] = round(float(np.percentile(a, PERCENTILES[name])), 2)
    out["max"] = round(float(a.max()), 2)
    return out
