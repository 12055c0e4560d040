"""The 40-digit passive boundaries of the limit tests' loops, as a stored table (not a test module).

Each end of each passive interval of ``K`` and ``B`` that :mod:`tests.test_analysis_limits`
checks is a mathematical constant of its loop: :func:`haptic_bus.bench.mp_boundary.reference_boundary`
finds it at 40 digits from the definitions (0.3 to 0.9 s of CPU each, 12 s for the table).  The
table ``tests/data/mp_boundaries.json`` holds them, rounded to doubles, with the double-precision
estimate each was searched from, where the boundary is attained (``kind``, ``theta``) and its
verification (passive just inside, active just outside, 1e-14 relative; stored as found: the
tests compare values, and D1's lower end of B, 3.3e-6 N s/m, is not verified at that step).  The test module reads
it and recomputes one entry of each ``kind`` (each branch of the reference) to show that the
table is what the reference says today.

Regenerate it after changing a loop of :data:`LOOPS` or the reference::

    python -m tests.mp_boundaries
"""

from __future__ import annotations

import json
import pathlib
from dataclasses import dataclass

from haptic_bus.analysis.limits import passive_limits
from haptic_bus.analysis.loop import WallLoop

TABLE = pathlib.Path(__file__).resolve().parent / "data" / "mp_boundaries.json"

D1 = WallLoop(0.5, 0.1, 1e-3, 100.0, 0.03, 1)  # the issue: max_damping said null
D2 = WallLoop(0.5, 0.1, 1e-3, 56.23, 0.03, 2)  # the issue: passive B only in about [0.013, 0.061]
REFERENCED = (  # every interval end of these is checked against the 40-digit reference
    WallLoop(0.032, 3.62, 1e-3, 400.0, 1.0, 1),
    WallLoop(0.5, 0.1, 1e-3, 20.0, 0.05, 0.5, "window:0.0003"),
    WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0, 0.3, "lowpass:0.0005"),
    WallLoop(1.0, 20.0, 1e-3, 5e3, 5.0, 1.25, "average"),
    WallLoop(0.032, 3.62, 1e-3, 700.0, 2.0, 0.25, "point"),
)
LOOPS = (D1, D2, *REFERENCED)


@dataclass(frozen=True)
class Boundary:
    """One stored end: the 40-digit boundary rounded to a double (N/m for ``K``, N s/m for ``B``)."""

    loop: WallLoop
    parameter: str  # "K" or "B"
    interval: int  # which passive interval of the parameter, in increasing order
    lower: bool  # the interval's lower end (active below), else its upper end
    estimate: float  # the double-precision end the reference was searched from
    value: float
    theta: float  # rad: where Re Z is zero at the boundary
    kind: str  # "flip (theta = pi)", "low frequency (theta -> 0)" or "tangency"
    verified: bool


def _loop_key(loop: WallLoop) -> list[object]:
    return [loop.m, loop.b, loop.T, loop.K, loop.B, loop.delay, str(loop.velocity), loop.discretisation.value]


def _key(loop: WallLoop, parameter: str, interval: int, lower: bool) -> str:
    return json.dumps([_loop_key(loop), parameter, interval, lower])


def read_table() -> dict[str, Boundary]:
    """The stored boundaries by (loop, parameter, interval, end)."""
    table = {}
    for entry in json.loads(TABLE.read_text()):
        loop = WallLoop(*entry["loop"][:7], discretisation=entry["loop"][7])
        boundary = Boundary(loop, entry["parameter"], entry["interval"], entry["lower"], entry["estimate"], entry["value"],
                            entry["theta"], entry["kind"], entry["verified"])
        table[_key(loop, boundary.parameter, boundary.interval, boundary.lower)] = boundary
    return table


def stored(table: dict[str, Boundary], loop: WallLoop, parameter: str, interval: int, lower: bool) -> Boundary:
    """The stored end, or an error saying how to regenerate the table."""
    key = _key(loop, parameter, interval, lower)
    assert key in table, f"no stored 40-digit boundary for {key}: run python -m tests.mp_boundaries"
    return table[key]


def compute() -> list[dict[str, object]]:
    """Every interval end of every loop of :data:`LOOPS`, searched at 40 digits (12 s of CPU)."""
    from haptic_bus.bench.mp_boundary import reference_boundary

    entries: list[dict[str, object]] = []
    for loop in LOOPS:
        for passive in passive_limits(loop):
            for interval, ends in enumerate(passive.intervals):
                for lower, estimate in zip((True, False), ends):
                    if lower and estimate == 0:  # passive from zero: no lower boundary
                        continue
                    ref = reference_boundary(loop, passive.parameter, estimate, lower=lower)
                    entries.append({"loop": _loop_key(loop), "parameter": passive.parameter, "interval": interval,
                                    "lower": lower, "estimate": estimate, "value": ref.value, "theta": ref.theta,
                                    "kind": ref.kind, "verified": ref.verified})
    return entries


if __name__ == "__main__":
    TABLE.write_text(json.dumps(compute(), indent=1) + "\n")
    print(f"wrote {TABLE}")
