"""Choosing a CAN bus the way python-can users configure one.

Explicit ``interface``/``channel``/``bitrate`` keyword arguments win; whatever is missing is
taken from python-can's own configuration chain (``can.rc``, the environment variables
``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE``/``CAN_CONFIG``, and the config files
``/etc/can.conf``, ``~/.can``, ``~/.canrc``; see :func:`can.util.load_config`).  Any
python-can interface works: ``virtual``, ``udp_multicast``, ``socketcan`` (``vcan0``,
``can0``), vendor adapters.

Frames stay on this host unless asked otherwise: python-can's ``udp_multicast`` sends with a
hop limit (IPv4 TTL) of 1, so every frame also leaves through the network interface.  Whenever
a configuration names no ``hop_limit`` for ``udp_multicast``, :func:`resolve_bus_config` sets
``hop_limit=0`` (the kernel then delivers to local sockets only).  A user who bridges two
machines over udp_multicast sets ``hop_limit`` on purpose (``--bus-option hop_limit=1``).
"""

from __future__ import annotations

import argparse
import configparser
import re
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from drives.errors import DriveError, ParameterError

if TYPE_CHECKING:
    import can

LOCAL_HOP_LIMIT = 0  # udp_multicast's default here: frames are delivered on this host only
MAX_HOP_LIMIT = 255  # the IP TTL / IPv6 hop limit field is one byte
MAX_PORT = 65535  # the UDP header's port field is two bytes (0: any port, no group's own)
IN_PROCESS_INTERFACES = ("virtual", "lockstep")  # buses inside one process: every node on them runs in it
BUS_OPTION_HELP = ("extra python-can bus argument, e.g. port=43113 (repeatable); udp_multicast gets hop_limit=0 "
                   "(frames stay on this host) unless you name one")
BUS_KWARGS_HELP = ("python-can's own spelling of --bus-option, as can.logger and can.viewer take it: one or more "
                   "KEY=VALUE after one flag (--bus-kwargs port=43113 hop_limit=0); the same values as --bus-option; "
                   "a key given twice with different values is refused")

NO_INTERFACE = ("--interface NAME and --channel CHANNEL (e.g. socketcan can0), CAN_INTERFACE and CAN_CHANNEL, "
                "a [default] section in python-can's config file ~/.canrc, or --modbus URL")
"""What a bus configuration that names no interface is refused with (``interface is missing; allowed: ...``,
exit 2): no bus given is invalid input, the same for every command that opens one."""


def resolve_bus_config(
    interface: str | None = None,
    channel: Any = None,
    bitrate: int | None = None,
    *,
    config_file: str | None = None,
    context: str | None = None,
    **kwargs: Any,
) -> dict[str, Any]:
    """The complete python-can bus configuration: explicit arguments over python-can's config chain
    (``udp_multicast`` with no ``hop_limit`` gets :data:`LOCAL_HOP_LIMIT`, module docstring); a
    configuration that names no interface anywhere is invalid input, :class:`ParameterError` (:data:`NO_INTERFACE`)."""
    given: dict[str, Any] = dict(kwargs)
    if interface is not None:
        given["interface"] = interface
    if channel is not None:
        given["channel"] = channel
    if bitrate is not None:
        given["bitrate"] = bitrate
    import can  # python-can on use: a command line that only parses never loads it

    where = f"bus {interface or '?'}:{channel if channel is not None else '?'}"
    if given.get("interface") == "udp_multicast":  # before python-can's own check, a ValueError (exit 1)
        _check_port(given.get("port"), where)
    try:
        config = dict(can.util.load_config(path=config_file, config=given, context=context))
    except (configparser.Error, UnicodeDecodeError) as exc:  # a ~/.canrc python-can cannot read: exit 2, one line
        raise ParameterError("python-can's config file", _config_file(exc, config_file),
                             f"an INI file with a [default] section ({' '.join(str(exc).split())})", "bus") from None
    except (can.CanInterfaceNotImplementedError, NotImplementedError, ValueError, TypeError) as exc:
        if "None" in str(exc):
            raise ParameterError("interface", None, NO_INTERFACE, "bus") from None
        unknown = interface if interface is not None else _unknown_interface(str(exc))
        if unknown is not None and unknown not in can.interfaces.VALID_INTERFACES:  # a typo, ours or a config's: exit 2
            origin = where if interface is not None else "bus (python-can's configuration: CAN_INTERFACE or ~/.canrc)"
            raise ParameterError("interface", unknown, "one of python-can's: "
                                 + ", ".join(sorted(can.interfaces.VALID_INTERFACES)), origin) from None
        raise DriveError(where, f"invalid CAN bus configuration: {exc}") from exc
    if not config.get("interface"):
        raise ParameterError("interface", None, NO_INTERFACE, "bus")
    rate = config.get("bitrate")
    if rate is not None and (isinstance(rate, bool) or not isinstance(rate, int) or rate <= 0):
        raise ParameterError("bitrate", rate, "a positive whole number of bit/s (the adapter names the rates it supports)",
                             where)
    if config["interface"] == "udp_multicast":
        hops = config.setdefault("hop_limit", LOCAL_HOP_LIMIT)
        if isinstance(hops, bool) or not isinstance(hops, int) or not 0 <= hops <= MAX_HOP_LIMIT:
            raise ParameterError("hop_limit", hops, f"a whole number of router hops in 0..{MAX_HOP_LIMIT} "
                                 f"(0: this host only)", where)
        group = config.get("channel")
        if not isinstance(group, str) or not group:  # python-can's TypeError traceback from inet_pton, exit 1
            raise ParameterError("channel", group, "a multicast group address, e.g. 239.74.163.2 or ff15::1 "
                                 "(--channel)", where)
        _check_port(config.get("port"), where)
    missing = _required_not_given(config)
    if missing:  # before any run folder or bus: python-can's TypeError when the bus is opened, exit 1
        raise _not_given(config["interface"], missing, where)
    return config


def _required_not_given(config: dict[str, Any]) -> list[str]:
    """The arguments the interface's bus class requires (no default) that ``config`` lacks, in its order;
    none when the class cannot be imported here (opening the bus says why)."""
    import importlib
    import inspect

    import can

    backend = can.interfaces.BACKENDS.get(config["interface"])
    if backend is None:
        return []
    try:
        bus_class = getattr(importlib.import_module(backend[0]), backend[1])
        parameters = list(inspect.signature(bus_class.__init__).parameters.values())[1:]
    except Exception:  # a vendor library missing, a module that fails to import: open_bus' DriveError says it
        return []
    named = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return [p.name for p in parameters if p.kind in named and p.default is p.empty and config.get(p.name) is None]


def _not_given(interface: str, missing: list[str], where: str) -> ParameterError:
    """``NAME is missing; allowed: ...`` for the first of an interface's required arguments not given."""
    flags = ", ".join("--channel" if name == "channel" else f"--bus-option {name}=VALUE" for name in missing)
    return ParameterError(missing[0], None, f"the {interface} bus' {', '.join(missing)} ({flags})", where)


def _unknown_interface(message: str) -> str | None:
    """The interface python-can's config chain named and python-can does not know (its message
    ``Unknown interface type "NAME"``), or None for any other complaint."""
    found = re.search(r'Unknown interface type "(.*)"', message)
    return found.group(1) if found else None


def _config_file(exc: Exception, config_file: str | None) -> str:
    """The config file python-can could not read: the one configparser names, else the one asked for,
    else python-can's list of files it reads."""
    named = getattr(exc, "source", None) or getattr(exc, "filename", None)
    if named:
        return str(named)
    if config_file:
        return config_file
    import can

    return " or ".join(str(path) for path in getattr(can.util, "CONFIG_FILES", ["~/.canrc"]))


def _check_port(port: object, where: str) -> None:
    """ParameterError unless ``port`` is None (python-can's default) or a UDP port a group can use."""
    if port is not None and (isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= MAX_PORT):
        raise ParameterError("port", port, f"a whole UDP port number in 1..{MAX_PORT}", where)


def open_bus(**arguments: Any) -> can.BusABC:
    """Open the python-can bus that :func:`resolve_bus_config` makes of ``arguments`` (the same
    keywords) (``udp_multicast``: :class:`drives.udp_multicast.FilteredMulticastBus`)."""
    import can

    config = resolve_bus_config(**arguments)
    channel = config.get("channel")
    where = f"bus {config.get('interface')}:{'?' if channel is None else channel}"  # no 'socketcan:None'
    try:
        if config["interface"] == "udp_multicast":  # the same interface, its filters applied before decoding
            from drives.udp_multicast import FilteredMulticastBus

            return FilteredMulticastBus(**{key: value for key, value in config.items() if key != "interface"})
        return can.Bus(**config)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise DriveError(where, f"cannot open the CAN bus: {exc}") from exc


def parse_bus_option(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` from a command line into a python-can bus argument (ints where they parse)."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=VALUE")
    try:
        return key, int(value, 0)
    except ValueError:
        return key, value


def as_typed(value: object) -> object:
    """An option's parsed value as the command line gave it: ``--bus-option`` pairs as ``KEY=VALUE``
    (``--bus-kwargs``' groups joined by spaces), a list of ids (``--node-ids 5,6``) joined by commas
    as it was typed (not ``'5 6'``, which reads as two arguments), anything else as it is."""
    if isinstance(value, list) and value and all(isinstance(item, int) for item in value):
        return ",".join(str(item) for item in value)
    if isinstance(value, list):
        return " ".join(str(as_typed(item)) for item in value)
    if isinstance(value, tuple) and len(value) == 2:
        return f"{value[0]}={value[1]}"
    return value


def merge_bus_options(*groups: Iterable[tuple[str, Any]]) -> dict[str, Any]:
    """The ``(key, value)`` pairs of ``--bus-option``, ``--bus-kwargs`` (and ``--interface``...) as one
    dict of python-can bus arguments; ParameterError when a key is given twice with different values."""
    merged: dict[str, Any] = {}
    for group in groups:
        for key, value in group:
            if key in merged and merged[key] != value:
                raise ParameterError(f"bus argument {key}", value,
                                     f"one value per key ({key} = {merged[key]!r} is given too)")
            merged[key] = value
    return merged
