"""The controller's tables of a profile that one-axis and multi-axis profiles share: ``[profile]``
(who uses it for what) and the policies ``[gate]``, ``[safety]``, ``[passivity]``,
``[supervisor]`` and ``[start]`` (read with
:class:`haptic_bus.profile.reader.Reader`; they need the control layer's types, so they live here
and not in :mod:`haptic_bus.profile`)."""

from __future__ import annotations

import pathlib
from dataclasses import dataclass

from drives.safety import ABORT_OPTIONS, SafetySettings
from haptic_bus.control.gate import BANDWIDTH_POLICIES, GatePolicy
from haptic_bus.control.passivity_layer import LAYER_MODES, LayerPolicy
from haptic_bus.control.supervisor import Action, SupervisorPolicy
from haptic_bus.profile.reader import NAME_PATTERN, Reader, profile_error

START_POLICIES = ("refuse", "ramp")


@dataclass(frozen=True)
class StartPolicy:
    """``[start]``: what a run does when the handle starts inside an object.  ``in_contact``:
    "refuse" (default: the drive is never enabled) or "ramp" (the scene's force from 0 to 1 over
    ``ramp_time`` s, every scaled wall on the way proven passive)."""

    in_contact: str = "refuse"
    ramp_time: float = 0.5


def read_about(top: Reader) -> tuple[str, str, str, str]:
    """``[profile]`` of the document ``top`` reads: its ``name``, ``operator``, ``task`` and ``description``."""
    meta = Reader(top.path, "profile", top.raw("profile", "a [profile] table"))
    about = (meta.text("name", pattern=NAME_PATTERN), meta.text("operator"), meta.text("task"), meta.text("description"))
    meta.done()
    return about


def read_gate(path: pathlib.Path, table: object) -> GatePolicy:
    """``[gate]``: safety_margin (N s/m) and bandwidth (a :data:`BANDWIDTH_POLICIES` name)."""
    r = Reader(path, "gate", table)
    margin = r.real("safety_margin", 0.0, 1e12, "N s/m")
    bandwidth = r.text("bandwidth", choices=BANDWIDTH_POLICIES)
    r.done()
    return GatePolicy(margin, bandwidth)


def read_safety(path: pathlib.Path, table: object) -> SafetySettings:
    """``[safety]`` (optional): heartbeat_ms, consumer_ms, rpdo_deadline_periods, abort_option
    ("fault", "disable-voltage", "quick-stop", "none"), strict, modbus_watchdog_ms (DESIGN 4.1)."""
    defaults = SafetySettings()
    if table is None:
        return defaults
    r = Reader(path, "safety", table)
    heartbeat = r.whole("heartbeat_ms", 1, 0xFFFF, default=defaults.heartbeat_ms)
    consumer = r.whole("consumer_ms", heartbeat + 1, 0xFFFF, default=max(defaults.consumer_ms, 3 * heartbeat))
    deadline = r.whole("rpdo_deadline_periods", 0, 10_000, default=defaults.rpdo_deadline_periods)
    option = r.text("abort_option", choices=tuple(ABORT_OPTIONS), default="fault")
    strict = r.flag("strict", default=defaults.strict)
    watchdog = r.whole("modbus_watchdog_ms", 0, 0xFFFF, default=defaults.modbus_watchdog_ms)
    r.done()
    return SafetySettings(defaults.master_node_id, heartbeat, consumer, deadline, ABORT_OPTIONS[option], strict, watchdog)


def read_passivity(path: pathlib.Path, table: object) -> LayerPolicy:
    """``[passivity]`` (optional): layer ("off", "guard", "bound"), budget_cap (J), beyond_gate."""
    defaults = LayerPolicy()
    if table is None:
        return defaults
    r = Reader(path, "passivity", table)
    layer = r.text("layer", choices=LAYER_MODES, default=defaults.layer)
    cap = r.real("budget_cap", 0.0, 1e6, "J", low_inclusive=False) if "budget_cap" in r.table else None
    beyond = r.flag("beyond_gate", default=False)
    r.done()
    if beyond and layer != "bound":
        raise profile_error(path, "passivity.beyond_gate", True, 'false unless layer = "bound" (only the bound '
                            "guarantees passivity for walls the gate refuses)")
    return LayerPolicy(layer, cap, beyond)


def read_supervisor(path: pathlib.Path, table: object, passivity: LayerPolicy) -> SupervisorPolicy:
    """``[supervisor]`` (optional): on_late, on_observer ("warn", "derate", "stop"), late_tolerance
    (fraction of T), late_window (cycles), late_limit (cycles), observer_limit (J).  A late cycle
    is a warning while a passivity layer holds the port passive, and stops a run without one."""
    defaults = SupervisorPolicy(on_late=Action.WARN.value if passivity.layer != "off" else Action.STOP.value)
    if table is None:
        return defaults
    r = Reader(path, "supervisor", table)
    actions = tuple(a.value for a in Action)
    on_late = r.text("on_late", choices=actions, default=defaults.on_late)
    tolerance = r.real("late_tolerance", 0.0, 100.0, "of the period T", low_inclusive=False, default=defaults.late_tolerance)
    window = r.whole("late_window", 1, 1_000_000, default=defaults.late_window)
    limit = r.whole("late_limit", 0, window - 1, default=min(defaults.late_limit, window - 1))
    on_observer = r.text("on_observer", choices=actions, default=defaults.on_observer)
    observer_limit = r.real("observer_limit", 0.0, 1e6, "J", default=defaults.observer_limit)
    r.done()
    return SupervisorPolicy(on_late, tolerance, window, limit, on_observer, observer_limit)


def read_start(path: pathlib.Path, table: object) -> StartPolicy:
    """``[start]`` (optional): in_contact ("refuse" or "ramp"), ramp_time (s)."""
    defaults = StartPolicy()
    if table is None:
        return defaults
    r = Reader(path, "start", table)
    policy = StartPolicy(r.text("in_contact", choices=START_POLICIES, default=defaults.in_contact),
                         r.real("ramp_time", 0.0, 3600.0, "s", low_inclusive=False, default=defaults.ramp_time))
    r.done()
    return policy
