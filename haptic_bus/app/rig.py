"""The one place haptic_bus reaches the simulated drive: the demo rig, ``haptic-bus sim``, the bench.

:func:`simulated_axes` does for a multi-axis profile what :func:`simulated_canopen` does for one
axis: the simulated device (:class:`sim_drive.canopen.multi_axis.MultiAxisSim`, one CANopen
slave per axis and the profile's hand in space) and the real multi-axis master
(:class:`drives.canopen.axes.CanopenAxes`) on one bus in this process.

:func:`simulated_canopen` runs a profile's loop against the simulated drive in this process
(``haptic-bus demo``, the end-to-end tests, the bench): the simulated drive is a real CANopen
slave (:class:`sim_drive.canopen.slave.CanopenSimDrive`) and the controller reaches it through
the real master (:class:`drives.canopen.drive.CanopenDrive`), frames and all.  By default they
share the lock-step bus (:mod:`drives.lockstep_bus`: each frame is served in the sender's
thread, so a virtual-time run is one thread, deterministic and free of thread hand-offs);
``interface="virtual"`` puts them on python-can's threaded virtual bus instead (the same
trajectories, bit for bit).  :func:`simulator_command` is how a second process starts it.
"""

from __future__ import annotations

import sys
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, cast

from haptic_bus.lazy import lazy_getattr

if TYPE_CHECKING:  # at run time each function imports what it uses: haptic-bus sim loads the simulator alone
    from drives.canopen.axes import CanopenAxes
    from drives.canopen.drive import CanopenDrive
    from haptic_bus.app.profiles import AxesProfile, Profile
    from sim_drive.bus_timing import BusLoadMeter, cycle_bits, frame_bits
    from sim_drive.canopen.multi_axis import MultiAxisSim
    from sim_drive.canopen.slave import CanopenSimDrive
    from sim_drive.eds import eds_path
    from sim_drive.modbus.multi_axis import MultiAxisModbusSim
    from sim_drive.modbus.server import ModbusSimServer, ServedUnit
    from sim_drive.operator import OperatorModel, operator_from_table
    from sim_drive.parameters import DeviceParameters, Timing
    from sim_drive.profile import SimulatedDevice, read_simulated_device
    from sim_drive.sync_clock import SyncClock

_EXPORTS = {  # the simulator's names this module hands on (__all__), each from its module, imported when first asked for
    "BusLoadMeter": "sim_drive.bus_timing", "cycle_bits": "sim_drive.bus_timing", "frame_bits": "sim_drive.bus_timing",
    "CanopenSimDrive": "sim_drive.canopen.slave", "DeviceParameters": "sim_drive.parameters",
    "ModbusSimServer": "sim_drive.modbus.server", "ServedUnit": "sim_drive.modbus.server",
    "MultiAxisModbusSim": "sim_drive.modbus.multi_axis", "MultiAxisSim": "sim_drive.canopen.multi_axis",
    "SimulatedDevice": "sim_drive.profile", "read_simulated_device": "sim_drive.profile", "eds_path": "sim_drive.eds",
    "operator_from_table": "sim_drive.operator",
}


__getattr__ = lazy_getattr(__name__, _EXPORTS, globals())  # from haptic_bus.app.rig import CanopenSimDrive: imported now


__all__ = [
    "BusLoadMeter",
    "CanopenSimDrive",
    "DeviceParameters",
    "ModbusSimServer",
    "MultiAxisModbusSim",
    "MultiAxisSim",
    "ServedUnit",
    "SimulatedDevice",
    "cycle_bits",
    "eds_path",
    "frame_bits",
    "operator_from_table",
    "profile_operator",
    "read_simulated_device",
    "sim_main",
    "simulated_axes",
    "simulated_axes_device",
    "simulated_canopen",
    "simulated_modbus",
    "simulator_command",
]


def simulator_command(*arguments: str) -> list[str]:
    """The command line that starts the simulated drive in another process (``python -m sim_drive``)."""
    return [sys.executable, "-m", "sim_drive", *arguments]


def sim_main(argv: Sequence[str]) -> int:
    """``haptic-bus sim ...``: the simulated drive's own command line, in this process."""
    from sim_drive.cli import main

    return main(list(argv))


def profile_operator(profile: Profile) -> OperatorModel:
    """The simulated operator the profile describes."""
    from sim_drive.operator import operator_from_table

    return operator_from_table(profile.operator_model, base=profile.path.parent if profile.path else None)


@contextmanager
def simulated_canopen(
    profile: Profile,
    *,
    node_id: int = 1,
    operator: OperatorModel | None = None,
    channel: str | None = None,
    substeps: int = 1,
    interface: str = "lockstep",
    sync_clock: SyncClock | None = None,
) -> Iterator[tuple[CanopenSimDrive, CanopenDrive]]:
    """Start the simulated drive and connect the master, enabled in CST; stop both on exit.

    ``substeps``: plant sub-steps per period with the operator force re-evaluated on each;
    ``interface``: ``"lockstep"`` (one thread) or ``"virtual"`` (python-can's, one thread per side);
    ``sync_clock``: how long each period the drive closes lasts (:mod:`sim_drive.sync_clock`;
    None: exactly ``T``).  The TPDOs carry the position (0x6064) for the port observer.
    """
    from drives.canopen.drive import DEFAULT_TPDO_WITH_POSITION, CanopenDrive
    from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, SafetySettings
    from sim_drive.canopen.slave import CanopenSimDrive
    from sim_drive.eds import eds_path
    from sim_drive.parameters import DeviceParameters

    channel = channel or f"haptic-bus-{uuid.uuid4().hex[:12]}"
    sim = CanopenSimDrive(
        {"interface": interface, "channel": channel},
        node_id,
        timing=profile.loop.timing,
        parameters=DeviceParameters(**cast(dict[str, Any], profile.sim_device_parameters()), substeps=substeps),
        operator=operator if operator is not None else profile_operator(profile),
        sync_clock=sync_clock,
    )
    sim.start()
    drive = CanopenDrive(node_id, interface=interface, channel=channel, period=profile.loop.period,
                         tpdo_objects=DEFAULT_TPDO_WITH_POSITION,
                         scaling=profile.scaling(), eds=eds_path(), safety=SafetySettings().for_virtual_time(profile.loop.period),
                         **VIRTUAL_TIME_CANOPEN_PATIENCE)
    try:
        drive.connect()
        drive.enable()
        yield sim, drive
    finally:
        drive.close()
        sim.stop()


def simulated_axes_device(profile: AxesProfile, bus: dict[str, Any], clock: str = "virtual") -> MultiAxisSim:
    """The simulated device a multi-axis profile describes (its axes' plants and hidden truth, its
    hand in space), not started, on ``bus`` (python-can keyword arguments); ``clock``: "virtual"
    (each SYNC advances the plants ``T``) or "wall" (the time between SYNCs, for a real-time run)."""
    from sim_drive.canopen.multi_axis import MultiAxisSim
    from sim_drive.space_operator import hand_from_table

    setups = [(cast(int, axis.node_id), parameters, timing) for axis, (parameters, timing) in zip(profile.axes,
                                                                                                  _axis_plants(profile))]
    return MultiAxisSim(bus, setups, hand_from_table(profile.operator_model, len(profile.axes)), clock=clock)


def _axis_plants(profile: AxesProfile) -> list[tuple[DeviceParameters, Timing]]:
    """Every axis' simulated plant (its ``[axes.device]`` and loop timing), in axis order."""
    from sim_drive.parameters import DeviceParameters, Timing

    return [(DeviceParameters(**cast(dict[str, Any], axis.device.sim_parameters(profile.period, axis.timing, axis.delay))),
             Timing(axis.timing)) for axis in profile.axes]


def simulated_modbus(device: SimulatedDevice, unit_ids: Sequence[int], servers: int = 1,
                     host: str = "127.0.0.1") -> ModbusSimServer | MultiAxisModbusSim:
    """The simulated ``device`` (what ``haptic-bus sim --profile`` reads, :func:`read_simulated_device`)
    over Modbus TCP on ``host``, each server on a free port, not started: a one-axis profile's drive,
    unit ``unit_ids[0]`` (its plant and operator); a multi-axis profile's, unit ``unit_ids[i]`` for
    axis ``i`` (their plants and the hand in space), on one server, or ``servers`` = one per axis."""
    from sim_drive.modbus.multi_axis import MultiAxisModbusSim
    from sim_drive.modbus.server import ModbusSimServer

    if device.multi_axis:
        setups = [(unit, axis.parameters, axis.timing) for unit, axis in zip(unit_ids, device.axes)]
        return MultiAxisModbusSim([(host, 0)] * servers, setups, device.make_hand())
    axis, operator = device.one_axis()
    return ModbusSimServer(host, 0, unit_id=unit_ids[0], timing=axis.timing, parameters=axis.parameters, operator=operator)


@contextmanager
def simulated_axes(profile: AxesProfile, *, channel: str | None = None,
                   interface: str = "lockstep") -> Iterator[tuple[MultiAxisSim, CanopenAxes]]:
    """Start the simulated multi-axis device and connect the multi-axis master (every axis maps
    0x6064), not enabled; stop both on exit.  ``interface``: "lockstep" (one thread) or "virtual"."""
    from drives.canopen.axes import CanopenAxes
    from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE, SafetySettings
    from sim_drive.eds import eds_path

    channel = channel or f"haptic-bus-{uuid.uuid4().hex[:12]}"
    sim = simulated_axes_device(profile, {"interface": interface, "channel": channel}).start()
    safety = SafetySettings().for_virtual_time(profile.period)
    axes = CanopenAxes([cast(int, axis.node_id) for axis in profile.axes],
                       scalings=[axis.device.scaling() for axis in profile.axes], interface=interface, channel=channel,
                       period=profile.period, eds=eds_path(), safety=safety, **VIRTUAL_TIME_CANOPEN_PATIENCE)
    try:
        axes.connect()
        yield sim, axes
    finally:
        axes.close()
        sim.stop()
