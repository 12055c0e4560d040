"""Typed errors of haptic_bus: each names what was wrong and what is allowed."""

from __future__ import annotations


class HapticBusError(Exception):
    """Base class of every error haptic_bus raises on purpose."""


class ParameterError(HapticBusError, ValueError):
    """A parameter is outside its allowed range (or not a number at all).

    Attributes name the parameter, the offending value and the allowed range, so a
    commissioning engineer can act on the message without reading code.
    """

    def __init__(self, name: str, value: object, allowed: str, context: str = "") -> None:
        self.name = name
        self.value = value
        self.allowed = allowed
        self.context = context
        where = f"{context}: " if context else ""
        super().__init__(f"{where}{name} = {value!r} is invalid; allowed: {allowed}")
