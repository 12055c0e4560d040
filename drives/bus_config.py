"""Choosing a CAN bus the way python-can users configure one.

Explicit ``interface``/``channel``/``bitrate`` keyword arguments win; whatever is missing is
taken from python-can's own configuration chain (``can.rc``, the environment variables
``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE``/``CAN_CONFIG``, and the config files
``/etc/can.conf``, ``~/.can``, ``~/.canrc``; see :func:`can.util.load_config`).  Any
python-can interface works: ``virtual``, ``udp_multicast``, ``socketcan`` (``vcan0``,
``can0``), vendor adapters.
"""

from __future__ import annotations

import argparse
from typing import Any

import can

from drives.errors import BusConfigError

_NO_INTERFACE = (
    "no CAN interface selected: pass interface=... (e.g. 'socketcan', 'virtual', 'udp_multicast'), "
    "or set CAN_INTERFACE/CAN_CHANNEL, or write a [default] section in ~/.canrc"
)


def resolve_bus_config(
    interface: str | None = None,
    channel: Any = None,
    bitrate: int | None = None,
    *,
    config_file: str | None = None,
    context: str | None = None,
    **kwargs: Any,
) -> dict[str, Any]:
    """The complete python-can bus configuration: explicit arguments over python-can's config chain."""
    given: dict[str, Any] = dict(kwargs)
    if interface is not None:
        given["interface"] = interface
    if channel is not None:
        given["channel"] = channel
    if bitrate is not None:
        given["bitrate"] = bitrate
    where = f"bus {interface or '?'}:{channel if channel is not None else '?'}"
    try:
        config = dict(can.util.load_config(path=config_file, config=given, context=context))
    except (can.CanInterfaceNotImplementedError, NotImplementedError, ValueError, TypeError) as exc:
        if "None" in str(exc):
            raise BusConfigError(where, _NO_INTERFACE) from exc
        raise BusConfigError(where, f"invalid CAN bus configuration: {exc}") from exc
    if not config.get("interface"):
        raise BusConfigError(where, _NO_INTERFACE)
    return config


def open_bus(
    interface: str | None = None,
    channel: Any = None,
    bitrate: int | None = None,
    *,
    config_file: str | None = None,
    context: str | None = None,
    **kwargs: Any,
) -> can.BusABC:
    """Open a python-can bus from explicit arguments and/or python-can's configuration chain."""
    config = resolve_bus_config(interface, channel, bitrate, config_file=config_file, context=context, **kwargs)
    where = f"bus {config.get('interface')}:{config.get('channel')}"
    try:
        return can.Bus(**config)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise BusConfigError(where, f"cannot open the CAN bus: {exc}") from exc


def parse_bus_option(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` from a command line into a python-can bus argument (ints where they parse)."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=VALUE")
    try:
        return key, int(value, 0)
    except ValueError:
        return key, value
