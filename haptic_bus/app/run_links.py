"""How a run reaches its drive(s): a :class:`Rig` per link, built before anything is touched.

- :func:`canopen_rig`: one CANopen drive or several axes' on one SYNC
  (:class:`drives.canopen.axes.CanopenAxes`; for one axis the controller gets the drive itself),
  once the node ids are usable (:func:`canopen_nodes`: an axis' 0x6064 mapped) and the bus can
  carry one SYNC and every axis' PDOs (:func:`haptic_bus.control.bus_load.axes_bus_load`);
- :func:`modbus_rig`: one Modbus drive or several axes' (:class:`drives.modbus.axes.ModbusAxes`:
  every unit polled in one cycle, on one server or a server per axis), the gate -- 1-D or coupled --
  judging at the loop delay each axis' poll gives (:func:`drives.modbus.timing.loop_delay`: the
  simulated drive's own, else from the whole cycle's measured round trip).

A rig says what ``run.json``'s ``link`` holds, how to open and commission the drive(s) (with the
gate and the upload server that go with them), and what the session knows of the drives beside:
the longest a torque target may be held (s), the shortest stall that faults them (s), the
addresses a fault reset reaches (one per axis), and whether there are CAN frames to log.  Units:
s, ms where named.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from typing import TYPE_CHECKING, Any

from drives.bus_config import resolve_bus_config
from drives.cia301 import NODE_ID_RANGE, NODE_IDS
from drives.cia402 import State
from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS
from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, VIRTUAL_TIME_MODBUS_PATIENCE, SafetySettings, patient
from haptic_bus.app.drive_address import DEFAULT_UNIT_ID, DriveAddress
from haptic_bus.app.profiles import AxesProfile, Profile
from haptic_bus.app.profiles.axes import DEFAULT_BITRATE
from haptic_bus.app.run_options import RunOptions
from haptic_bus.control.bus_load import axes_bus_load
from haptic_bus.errors import DriveError, ParameterError, Refusal
from haptic_bus.validation import one_or_one_each, typed_repeat

if TYPE_CHECKING:
    import can

    from drives.canopen.link import NetworkLink, Tap
    from drives.cia402_master import Cia402Master
    from drives.modbus.drive import ModbusDrive
    from haptic_bus.control.controller import WallController
    from haptic_bus.node.controller_node import ControllerNode

logger = logging.getLogger(__name__)

DEFAULT_CONTROLLER_NODE_ID = 127
PROFILE_SCALING_SOURCE = "profile [device]"  # how the profile's scaling values are named in the report
RUN_MAPPING = "with-position"  # the TPDO mapping a run needs: 0x6064 every cycle

Serve = Callable[["WallController[Any, Any]"], "ControllerNode | None"]  # the upload server for a controller (None: none)
Opened = tuple[Any, Any, Serve]  # the drive(s), their gate, the upload server
OpenDrive = Callable[[ExitStack, "Tap | None"], Opened]


@dataclasses.dataclass(frozen=True)
class Watchdog:
    """The shortest stall (s) that faults the drive (inf: none), and the RPDO deadline in periods
    when that is the binding one (a longer ``T`` lengthens it), else None; ``at(T)``: the shortest stall
    at another ``T`` (None: the same at any ``T``)."""

    stall: float
    periods: int | None
    at: Callable[[float], float] | None = None


@dataclasses.dataclass
class Rig:
    """One run's link: ``link`` (``run.json``'s, completed as the drives are commissioned); ``open``
    the drive(s), commissioned, with their gate and upload server; ``hold``, the longest a drive
    may hold one torque target (s, the ``bound`` layer's budget); its ``watchdog`` (pre-flight);
    ``addresses`` a fault reset reaches, one per axis in axis order (none: no reset possible, an
    open bus); ``frames``: whether there are CAN frames to log; ``check``: what refuses the run
    before any bus is opened (:class:`Refusal`); ``safety``: the safety settings the drive(s) are
    given (in virtual time the profile's with the watchdogs' floor,
    :meth:`~drives.safety.SafetySettings.for_virtual_time`: ``run.json``'s ``settings.safety``)."""

    link: dict[str, Any]
    open: OpenDrive
    hold: float
    watchdog: Watchdog
    addresses: tuple[DriveAddress, ...]
    frames: bool = False
    check: Callable[[], None] = lambda: None
    safety: SafetySettings | None = None

    def fault_hint(self, axis: int | None) -> str | None:
        """What clears the fault of axis ``axis`` (its index; None: unknown): its ``haptic-bus
        fault-reset`` command (None where no address reaches it)."""
        if axis is not None and axis < len(self.addresses):
            return self.addresses[axis].fault_reset_hint()
        return self.addresses[0].fault_reset_hint() if len(self.addresses) == 1 else None


def longest_hold(period: float, wall_paced: bool, deadline_ms: int, fallback_ms: int) -> float:
    """How long (s) the drive may hold one torque target before its watchdog removes it: the
    ``bound`` layer's budget per target.  In virtual time the simulated plant advances one
    period per SYNC, so a target acts exactly ``period``; wall-paced (``wall_paced``) up to the drive's receive
    deadline (RPDO deadline, Modbus watchdog; else ``fallback_ms``, the heartbeat consumer) plus
    the period it was latched for.  With no watchdog at all nothing bounds it: ``inf``."""
    if not wall_paced:
        return period
    watchdog = deadline_ms or fallback_ms
    return watchdog / 1000.0 + period if watchdog else math.inf


def canopen_watchdog(safety: SafetySettings, period: float) -> Watchdog:
    """The shortest stall that faults a CANopen drive with these settings at period ``period`` s
    (:meth:`~drives.safety.SafetySettings.canopen_stall`), and the RPDO deadline's periods when that
    is the binding one."""
    stall = safety.canopen_stall(period)
    binding = safety.rpdo_deadline_periods and safety.rpdo_deadline_ms(period) / 1000.0 <= stall
    return Watchdog(stall, safety.rpdo_deadline_periods if binding else None, safety.canopen_stall)


def given_safety(safety: SafetySettings, period: float, options: RunOptions) -> SafetySettings:
    """The safety settings a run at ``T = period`` s gives its drive(s): ``safety`` wall-paced, else
    with the watchdogs' floor of virtual time."""
    return safety if options.wall_paced else safety.for_virtual_time(period)


def _serve(stack: ExitStack, link: NetworkLink, name: str, node_id: int, heartbeat_ms: int) -> Serve:
    """The controller as CANopen node ``node_id`` on the drives' own network (one handle, read by the
    control thread): gated uploads of the scene's walls, judged in the judge process."""
    from haptic_bus.node.controller_node import ControllerNode
    from haptic_bus.node.verdicts import judge_pool

    judge_pool()  # the judge worker started now, before the control thread's real-time session: it keeps its scheduling

    def serve(controller: WallController[Any, Any]) -> ControllerNode:
        if link.network is None:
            raise DriveError(name, "the CAN network has no bus after connecting")
        node = ControllerNode(controller, node_id, heartbeat_ms)
        node.attach(link.network)
        stack.callback(node.detach)
        return node

    return serve


def canopen_rig(profile: Profile | AxesProfile, bus: can.BusABC | Mapping[str, Any], options: RunOptions,
                node_id: int | None = None, controller_node_id: int = DEFAULT_CONTROLLER_NODE_ID) -> Rig:
    """The CANopen drive(s) on ``bus`` (python-can keyword arguments, or an open :class:`can.BusABC`
    the caller owns: the run neither closes it nor sets its filters; then ``reset_fault`` is
    refused): drive ``node_id`` for a one-axis profile, each ``[[axes]]`` node for several, on one
    SYNC (:class:`~drives.canopen.axes.CanopenAxes`; one axis: the controller gets its drive, whose
    cycle of one is its scalar path), the controller node ``controller_node_id`` beside them.
    Checked before any bus is opened: the node ids (:func:`canopen_nodes`); the bus load of one
    SYNC and every axis' PDOs at the bus' bitrate (python-can's, else a multi-axis profile's
    ``[bus] bitrate``, else 1 Mbit/s), above 70 % refused (:class:`Refusal`, exit 1)."""
    import can

    from drives.canopen.axes import CanopenAxes
    from drives.canopen.drive import DEFAULT_TPDO_WITH_POSITION, CanopenDrive

    if not isinstance(bus, (Mapping, can.BusABC)):
        raise ParameterError("bus", bus, "python-can keyword arguments (a mapping) or an open can.BusABC", "run")
    several = isinstance(profile, AxesProfile)
    nodes = canopen_nodes(profile, node_id, controller_node_id)
    given = None if isinstance(bus, Mapping) else bus
    if given is not None and getattr(given, "_is_shutdown", False):  # python-can's own flag, set by shutdown()
        raise ParameterError("bus", given, "an open can.BusABC (this one is shut down)", "run")
    if given is not None and options.reset_fault:
        raise ParameterError("reset_fault", True, "False with an open bus (the reset needs a bus configuration)", "run")
    config = resolve_bus_config(**bus) if isinstance(bus, Mapping) else \
        {"interface": type(bus).__name__, "channel": bus.channel_info}  # before any file: an unknown interface is exit 2
    period = profile.period
    safety = dataclasses.replace(profile.safety, master_node_id=controller_node_id)
    bitrate = float(config.get("bitrate") or (profile.bitrate if isinstance(profile, AxesProfile) else DEFAULT_BITRATE))
    link: dict[str, Any] = {"kind": "canopen", "bus": {k: str(v) for k, v in config.items()},
                            **({"node_ids": nodes} if several else {"node_id": nodes[0]}),
                            "controller_node_id": controller_node_id, "upload_server": True, "bus_log": options.bus_log,
                            "bitrate_checked": bitrate}
    where = ({"bus": given} if given is not None else
             {"interface": config["interface"], "channel": config.get("channel"), "bitrate": config.get("bitrate"),
              "bus_kwargs": {k: v for k, v in config.items() if k not in ("interface", "channel", "bitrate")}})

    def check() -> None:
        try:
            load = axes_bus_load([RUN_MAPPING] * len(nodes), bitrate, period)
        except ParameterError as refusal:
            raise Refusal(f"the bus cannot carry this cycle; allowed: {refusal.allowed}") from None
        link["bus_load"] = dataclasses.asdict(load)

    def open_drive(stack: ExitStack, tap: Tap | None) -> Opened:
        axes = CanopenAxes(nodes, scalings=profile.scalings(), **where, period=period,
                           tpdo_objects=DEFAULT_TPDO_WITH_POSITION, scaling_source=PROFILE_SCALING_SOURCE,
                           safety=given_safety(safety, period, options),
                           **patient(options.wall_paced, VIRTUAL_TIME_CANOPEN_PATIENCE))
        stack.callback(axes.close)
        axes.link.tap = tap  # before commissioning: its frames are logged too
        axes.connect()

        def per_drive(value: Callable[[CanopenDrive], list[str]]) -> Any:  # several: by drive name
            return {drive.name: value(drive) for drive in axes.drives} if several else value(axes.drives[0])

        link["safety_warnings"] = per_drive(lambda drive: list(drive.safety_warnings))
        link["pdo_mapping_notes"] = per_drive(lambda drive: list(drive.commissioned.mapping_notes)
                                              if drive.commissioned else [])
        for drive in axes.drives:
            _show_scaling(drive, options, f" of {drive.name}" if several else "")
        serve = _serve(stack, axes.link, axes.name, controller_node_id, safety.heartbeat_ms)
        return (axes if several else axes.drives[0]), profile.gate(), serve

    hold = longest_hold(period, options.wall_paced, safety.rpdo_deadline_ms(period), safety.consumer_ms)
    addresses = tuple(DriveAddress(bus=dict(bus), node_id=node) for node in nodes) if isinstance(bus, Mapping) else ()
    return Rig(link, open_drive, hold, canopen_watchdog(safety, period), addresses, frames=True, check=check,
               safety=given_safety(safety, period, options))


def canopen_nodes(profile: Profile | AxesProfile, node_id: int | None, controller_node_id: int) -> list[int]:
    """Each axis' CANopen node id: ``node_id`` for a one-axis profile, the ``[[axes]]`` node ids (each
    mapping 0x6064: the port observer and the passivity layer read it every cycle) for several;
    each in :data:`~drives.cia301.NODE_ID_RANGE`, none twice, and ``controller_node_id`` none of them.  ParameterError (exit 2)
    naming :func:`~haptic_bus.app.runner.run`'s argument, or the profile's field, otherwise."""
    if isinstance(profile, AxesProfile):
        where = f"profile {profile.path or profile.name}"
        for i, axis in enumerate(profile.axes):
            if axis.node_id is None:
                raise ParameterError(f"axes[{i}].node_id", None, "a node_id per axis on a CAN bus (Modbus axes: give "
                                     "the Modbus URL, --modbus)", where)
        for i, axis in enumerate(profile.axes):
            if axis.mapping != RUN_MAPPING:
                raise ParameterError(f"axes[{i}].mapping", axis.mapping, f'"{RUN_MAPPING}" for a run: the port observer '
                                     "and the passivity layer read 0x6064 every cycle", where)
        named = [(f"axes[{i}].node_id", axis.node_id, where) for i, axis in enumerate(profile.axes)]
    else:
        named = [("node_id", node_id, "run")]
    for name, value, context in (*named, ("controller_node_id", controller_node_id, "run")):
        if isinstance(value, bool) or not isinstance(value, int) or not NODE_ID_RANGE[0] <= value <= NODE_ID_RANGE[1]:
            raise ParameterError(name, value, NODE_IDS, context)
    nodes = [value for _, value, _ in named if isinstance(value, int)]
    if len(set(nodes)) != len(nodes):
        raise ParameterError("node_ids", nodes, "a node id per axis, none twice", named[0][2])
    if controller_node_id in nodes:
        allowed = f"other than the drive's ({nodes[0]})" if len(nodes) == 1 else f"none of the axes has ({nodes})"
        raise ParameterError("controller_node_id", controller_node_id, f"a node id {allowed}", "run")
    return nodes


def modbus_units(profile: Profile | AxesProfile, urls: Sequence[str], unit_ids: Sequence[int] | None) -> list[int]:
    """Each axis' Modbus unit id: ``unit_ids`` (one per axis), else the profile's ``[[axes]]`` unit
    ids, else unit 1 on each server where there is one URL per axis; ParameterError (exit 2) naming
    what is missing or out of :data:`~drives.modbus.register_map.UNIT_ID_RANGE`, before anything is
    touched.  ``urls``: one for every axis, or one per axis."""
    size = len(profile.axes) if isinstance(profile, AxesProfile) else 1
    one_or_one_each("bus", urls, size, "axis", context="run")
    stated = [axis.unit_id for axis in profile.axes] if isinstance(profile, AxesProfile) else [None]
    if isinstance(unit_ids, (str, bytes)):  # a sequence of characters, not of unit ids
        raise ParameterError("unit_ids", unit_ids, f"{UNIT_IDS}, a list of them, one per axis", "run")
    if unit_ids is not None:
        units = list(unit_ids)
    elif None not in stated:
        units = [unit for unit in stated if unit is not None]
    elif len(urls) == size:
        units = [DEFAULT_UNIT_ID] * size
    else:
        raise ParameterError("unit_ids", None, f"one Modbus unit id per axis ({size}, e.g. "
                             f"{','.join(str(i + 1) for i in range(size))}): the profile's [[axes]] state none", "run")
    low, high = UNIT_ID_RANGE
    if any(isinstance(unit, bool) or not isinstance(unit, int) or not low <= unit <= high for unit in units):
        name, value = ("unit_ids", units) if isinstance(profile, AxesProfile) else ("unit_id", units[0])
        raise ParameterError(name, value, f"{UNIT_IDS}: the units that answer (0 is broadcast)", "run")
    twice = shared_place(urls, units)
    if unit_ids is None and len(urls) == size and twice is not None:  # no unit ids were given
        shown, given = typed_repeat(urls)
        raise ParameterError("bus", shown, f"one for every axis, or a different one per axis ({size} axes; {given}): "
                             "several axes on one server: one URL with the unit ids", "run")
    if len(units) != size:
        raise ParameterError("unit_ids", units, f"{size} unit ids, one per axis", "run")
    if twice is not None:
        raise ParameterError("unit_ids", units, f"{size} unit ids, one per axis, {none_twice(*twice)}", "run")
    return units


def shared_place(urls: Sequence[str], units: Sequence[int]) -> tuple[int, str] | None:
    """The first unit and URL two axes share (``urls``: one for every axis, or one per axis), or None."""
    places = list(zip(units, list(urls) * len(units) if len(urls) == 1 else urls))
    return next((place for i, place in enumerate(places) if place in places[:i]), None)


def none_twice(unit: int, url: str) -> str:
    """What a refusal of a unit id two axes share at one URL allows, naming the two."""
    return f"none twice at one URL (unit {unit} is given twice at {url})"


def modbus_rig(profile: Profile | AxesProfile, urls: Sequence[str], unit_ids: Sequence[int], options: RunOptions) -> Rig:
    """The Modbus drive(s): unit ``unit_ids[i]`` of axis ``i`` at ``urls[i]`` (``tcp://HOST:PORT`` or
    ``rtu:/dev/...``; one URL: every axis' units on one server), every axis polled in one cycle
    (:class:`~drives.modbus.axes.ModbusAxes`); the gate (1-D, or coupled for several axes) judges at
    each axis' loop delay: the simulated drive's own, else the whole cycle's measured poll
    (:func:`~drives.modbus.timing.loop_delay`).  No upload server over Modbus."""
    from drives.modbus.axes import ModbusAxes
    from drives.modbus.drive import ModbusDrive
    from drives.modbus.timing import loop_delay, measure_poll

    several = isinstance(profile, AxesProfile)
    places = list(zip(list(urls) * len(unit_ids) if len(urls) == 1 else urls, unit_ids))
    period = profile.period
    safety = given_safety(profile.safety, period, options)
    link: dict[str, Any] = ({"kind": "modbus", "urls": [url for url, _ in places], "unit_ids": list(unit_ids)} if several
                            else {"kind": "modbus", "url": places[0][0], "unit_id": places[0][1]})

    def open_drive(stack: ExitStack, tap: Tap | None) -> Opened:
        drives = [ModbusDrive.from_url(url, unit_id=unit, scaling=scaling, scaling_source=PROFILE_SCALING_SOURCE,
                                       safety=safety, with_position=True,
                                       **patient(options.wall_paced, VIRTUAL_TIME_MODBUS_PATIENCE))
                  for (url, unit), scaling in zip(places, profile.scalings())]
        axes = ModbusAxes(drives)
        stack.callback(axes.close)
        axes.connect()  # reads only: identity, scaling, timing; a unit nobody answers for is named
        _refuse_another_master(drives)  # before the poll measurement, which writes
        for drive in drives:
            _show_scaling(drive, options, f" of {drive.name}" if several else "")
        poll = None if axes.simulated else measure_poll(axes, 500)
        delays = [loop_delay(drive, period, poll) for drive in drives]
        link["poll"] = None if poll is None else dataclasses.asdict(poll)
        logger.info("Modbus poll: the gate assumes a loop delay of %s sample(s)", ", ".join(f"{d:.4g}" for d in delays))
        gate: Any = profile.gate(delays)  # the 1-D or the coupled gate: each admits its kind of scene
        if not profile.passivity.beyond_gate:  # the profile was judged at its own timing's delay
            gate.admit(profile.compiled_scene())
        return (axes if several else drives[0]), gate, lambda controller: None  # no upload server over Modbus

    hold = longest_hold(period, options.wall_paced, safety.modbus_watchdog_ms, 0)
    watchdog = Watchdog(safety.modbus_watchdog_ms / 1000.0 if safety.modbus_watchdog_ms else math.inf, None)
    return Rig(link, open_drive, hold, watchdog, tuple(DriveAddress(url=url, unit_id=unit) for url, unit in places),
               safety=safety)


def _refuse_another_master(drives: Sequence[ModbusDrive]) -> None:
    """A drive already OPERATION ENABLED when we arrive is driven by another master (every run
    leaves it disabled, and its watchdog faults it when a master dies): refuse before writing
    anything to any of ``drives``, rather than disable them under that master -- every link is
    left without a write, not only that drive's (closing the others' live links wrote their safe
    outputs: a refused run disabled two units of a running three-axis run).  (The CANopen master
    does the same, and also listens for another SYNC, at commissioning.)"""
    for drive in drives:
        if drive.state() is State.OPERATION_ENABLED:
            for each in drives:
                each.link.drop()  # leave without a write: closing a live link writes the safe outputs, disabling it
            raise DriveError(drive.name, "the drive is in OPERATION ENABLED before this master enabled it: another "
                                         "master drives it; stop that master, or disable the drive, before starting "
                                         "this one")


def _show_scaling(drive: Cia402Master, options: RunOptions, of: str = "") -> None:
    """Say where each scaling factor came from (run.json records it too), unless the run is quiet;
    ``of``: which drive, for several."""
    if options.live and drive.scaling_report is not None:
        print("\n".join(f"scaling{of}: {line}" for line in drive.scaling_report.lines()), flush=True)
