"""Timing helpers of the benchmark: every figure a median with its min-max over repeats, the machine.

Every timing the benchmark quotes is a :class:`Spread` over at least :data:`REPEATS` repeats
taken in the same run as the figure it is compared with; a ratio of two timings is measured
pairwise (:func:`paired`: the two alternate, repeat by repeat, and each pair gives one ratio),
so a machine that slows down for a while slows both sides of the pair.  Absolute times are
reported, never asserted.
"""

from __future__ import annotations

import datetime
import os
import platform
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

REPEATS = 5  # the least number of repeats behind any timing
_PACKAGES = ("numpy", "scipy", "mpmath", "control", "canopen", "python-can", "pymodbus", "matplotlib")


@dataclass(frozen=True)
class Spread:
    """One figure over repeats: ``median``, ``low`` (min), ``high`` (max) and how many ``repeats``."""

    median: float
    low: float
    high: float
    repeats: int

    @classmethod
    def of(cls, samples: Sequence[float]) -> Spread:
        """The spread of ``samples`` (at least one)."""
        values = list(samples)
        return cls(float(statistics.median(values)), float(min(values)), float(max(values)), len(values))

    def scaled(self, factor: float) -> Spread:
        """Every figure times ``factor`` (> 0), e.g. per cycle from per run."""
        return Spread(self.median * factor, self.low * factor, self.high * factor, self.repeats)

    def rate(self, count: float) -> Spread:
        """``count`` per the timed seconds (e.g. cycles/s from seconds per run): min and max swap."""
        return Spread(count / self.median, count / self.high, count / self.low, self.repeats)

    def to_dict(self) -> dict[str, float | int]:
        """JSON-ready: ``median``, ``min``, ``max``, ``repeats``."""
        return {"median": self.median, "min": self.low, "max": self.high, "repeats": self.repeats}


def _batch(func: Callable[[], Any], calls: int) -> float:
    start = time.perf_counter_ns()
    for _ in range(calls):
        func()
    return (time.perf_counter_ns() - start) * 1e-9


def calibrate(func: Callable[[], Any], min_ns: int = 2_000_000, max_calls: int = 1_000_000) -> int:
    """Calls per batch so that one batch of ``func()`` takes at least ``min_ns`` (doubling from 1)."""
    calls = 1
    while True:
        elapsed = _batch(func, calls) * 1e9
        if elapsed >= min_ns or calls >= max_calls:
            return calls
        calls *= 2 if elapsed * 4 > min_ns else 8


def time_per_call(func: Callable[[], Any], *, repeats: int = REPEATS, min_ns: int = 2_000_000,
                  max_calls: int = 1_000_000) -> Spread:
    """Seconds per call of ``func()`` over ``repeats`` batches, each lasting >= ``min_ns``.

    The batch size is calibrated once (doubling until one batch takes ``min_ns``), so a
    sub-microsecond call is timed over thousands of calls and a slow one over one call.
    """
    calls = calibrate(func, min_ns, max_calls)
    return Spread.of([_batch(func, calls) / calls for _ in range(max(repeats, REPEATS))])


def repeated(measure: Callable[[], float], repeats: int = REPEATS) -> Spread:
    """``measure()`` (one whole measurement, e.g. seconds of one run) ``repeats`` times."""
    return Spread.of([measure() for _ in range(max(repeats, REPEATS))])


def paired(first: Callable[[], float], second: Callable[[], float],
           repeats: int = REPEATS) -> tuple[Spread, Spread, Spread]:
    """``first()`` and ``second()`` alternately ``repeats`` times: their spreads, and the spread of
    the per-pair ratio ``first/second``."""
    a, b = [], []
    for _ in range(max(repeats, REPEATS)):
        a.append(first())
        b.append(second())
    return Spread.of(a), Spread.of(b), Spread.of([x / y for x, y in zip(a, b)])


def paired_calls(first: Callable[[], Any], second: Callable[[], Any], repeats: int = REPEATS,
                 min_ns: int = 2_000_000) -> tuple[Spread, Spread, Spread]:
    """:func:`paired` on seconds per call of ``first()`` and ``second()`` (each batch calibrated once)."""
    n1, n2 = calibrate(first, min_ns), calibrate(second, min_ns)
    return paired(lambda: _batch(first, n1) / n1, lambda: _batch(second, n2) / n2, repeats)


def timed_once(func: Callable[[], Any]) -> tuple[float, Any]:
    """``(seconds, result)`` of one call of ``func()``."""
    start = time.perf_counter_ns()
    result = func()
    return (time.perf_counter_ns() - start) * 1e-9, result


def _version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _cpu_model() -> str | None:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def machine() -> dict[str, Any]:
    """Platform, CPU, Python and package versions, the load average, and the date (UTC, ISO 8601)."""
    try:
        load = list(os.getloadavg())
    except OSError:
        load = None
    return {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "load_average": load,
        "python": platform.python_version(),
        "python_implementation": platform.python_implementation(),
        "versions": {name: _version(name) for name in _PACKAGES},
    }
