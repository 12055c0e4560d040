"""Timing helpers of the benchmark: medians of repeated ``perf_counter_ns`` runs, the machine.

Every figure the benchmark quotes is a median of repeats taken in the same run as the figure
it is compared with; absolute times are reported, never asserted.
"""

from __future__ import annotations

import datetime
import os
import platform
import statistics
import time
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

_PACKAGES = ("numpy", "scipy", "mpmath", "control", "canopen", "python-can", "pymodbus", "matplotlib")


def time_per_call(func: Callable[[], Any], *, repeats: int = 7, min_ns: int = 2_000_000, max_calls: int = 1_000_000) -> float:
    """Median seconds per call of ``func()`` over ``repeats`` batches, each lasting >= ``min_ns``.

    The batch size is calibrated once (doubling until one batch takes ``min_ns``), so a
    sub-microsecond call is timed over thousands of calls and a slow one over one call.
    """
    calls = 1
    while True:
        start = time.perf_counter_ns()
        for _ in range(calls):
            func()
        elapsed = time.perf_counter_ns() - start
        if elapsed >= min_ns or calls >= max_calls:
            break
        calls *= 2 if elapsed * 4 > min_ns else 8
    samples = [elapsed / calls]
    for _ in range(repeats - 1):
        start = time.perf_counter_ns()
        for _ in range(calls):
            func()
        samples.append((time.perf_counter_ns() - start) / calls)
    return statistics.median(samples) * 1e-9


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
    """Platform, CPU, Python and package versions, and the date (UTC, ISO 8601)."""
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "python_implementation": platform.python_implementation(),
        "versions": {name: _version(name) for name in _PACKAGES},
    }
