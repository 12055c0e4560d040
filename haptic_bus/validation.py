"""Checks that turn user numbers into validated floats and ints, or raise ParameterError."""

from __future__ import annotations

import math
import numbers

from drives.errors import ParameterError


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

    ``low``/``high`` bound the range (``high`` always inclusive); ``unit`` only decorates
    the message.
    """
    bracket = "[" if low_inclusive else "("
    allowed = f"a finite real in {bracket}{low:g}, {high:g}]" + (f" {unit}" if unit else "")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ParameterError(name, value, allowed, context)
    number = float(value)
    if not math.isfinite(number):
        raise ParameterError(name, value, allowed, context)
    below = number < low if low_inclusive else number <= low
    if below or number > high:
        raise ParameterError(name, value, allowed, context)
    return number


def whole_in_range(name: str, value: object, low: int, high: int, *, context: str = "") -> int:
    """Return ``value`` as an int if it is a whole number in ``[low, high]``, else raise."""
    allowed = f"an integer in [{low}, {high}]"
    if isinstance(value, bool):
        raise ParameterError(name, value, allowed, context)
    if isinstance(value, numbers.Integral):
        whole = int(value)
    elif isinstance(value, numbers.Real) and math.isfinite(float(value)) and float(value).is_integer():
        whole = int(float(value))
    else:
        raise ParameterError(name, value, allowed, context)
    if not low <= whole <= high:
        raise ParameterError(name, value, allowed, context)
    return whole
