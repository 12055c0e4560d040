"""The check of a real number in a range every layer shares, and the words its refusal states.

``drives`` is the bottom layer and imports nothing of ours, so the check lives here, beside nothing but
:mod:`drives.errors`; :mod:`haptic_bus.validation` re-exports it (the base loads this plain module and
``drives.errors``, nothing of a bus), and ``drives``' own arguments (a scan's time budget) use it too.
"""

from __future__ import annotations

import math
import numbers

from drives.errors import ParameterError


def real_range(low: float, high: float, unit: str = "", *, low_inclusive: bool = True) -> str:
    """What :func:`real_in_range` allows, as its refusal states it: ``a finite real in [low, high] unit``, or
    ``a finite real > low unit`` (``>=`` when ``low_inclusive``) for a ``high`` of infinity (no upper bound)."""
    if math.isinf(high):
        span = f"{'>=' if low_inclusive else '>'} {low:g}"
    else:
        span = f"in {'[' if low_inclusive else '('}{low:g}, {high:g}]"
    return f"a finite real {span}" + (f" {unit}" if unit else "")


def real_in_range(
    name: str,
    value: object,
    low: float,
    high: float,
    *,
    low_inclusive: bool = True,
    unit: str = "",
    context: str = "",
) -> float:
    """Return ``value`` as a Python float if it is a finite real in the range, else raise.

    ``low``/``high`` bound the range (``high`` always inclusive; infinity for none); ``unit`` only
    decorates the message.
    """
    allowed = real_range(low, high, unit, low_inclusive=low_inclusive)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ParameterError(name, value, allowed, context)
    number = float(value)
    if not math.isfinite(number):
        raise ParameterError(name, value, allowed, context)
    below = number < low if low_inclusive else number <= low
    if below or number > high:
        raise ParameterError(name, value, allowed, context)
    return number
