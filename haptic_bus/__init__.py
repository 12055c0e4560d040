"""haptic_bus: passive virtual walls rendered through a servo drive on a fieldbus.

SI units everywhere inside this package: kg, N, m, s, N/m, N s/m.  The public API, so that
users write ``haptic_bus.check_passivity(...)``, never a module path::

    import haptic_bus as hb

    if __name__ == "__main__":  # a run starts worker processes (spawn), which import this file again
        report = hb.check_passivity(mass=0.5, friction=0.1, period=1e-3, stiffness=200, damping=100, delay=1)
        report.passive, report.margin, report.max_stiffness, report.to_dict()

        profile = hb.load_profile("cia402-handle")            # validated and gated: a Profile (one axis)
        # the drive: any CANopen drive, here the simulated one of the same profile, started as
        #   haptic-bus sim --profile cia402-handle --interface udp_multicast --channel 239.74.163.2 \
        #       --bus-option port=43113 --node-id 5
        bus = {"interface": "udp_multicast", "channel": "239.74.163.2", "port": 43113}  # or an open can.BusABC
        result = hb.run(profile, bus, hb.RunOptions(duration=1.0, pacing="virtual"), node_id=5)
        result.exit_reason, result.summary.cycles, result.folder  # "completed", 1000, runs/<UTC>-cia402-handle

``hb.load_profile`` loads either kind of profile: a file with ``[[axes]]`` gives an :class:`AxesProfile`
(``hb.load_profile("gantry-3d")``: validated, its bus load checked, its scene judged by the coupled
gate), one without it a :class:`Profile`.  The same ``hb.run`` runs either kind (several axes against
``haptic-bus sim --node-ids 5,6,7 --profile gantry-3d``: the node ids come from the profile), a Modbus
drive (``bus`` a URL, ``"tcp://127.0.0.1:5020"``, with ``unit_id``) and several Modbus axes
(``bus`` one URL, or a list of one per axis, with ``unit_ids=[1, 2, 3]``, against ``haptic-bus sim
--modbus tcp://127.0.0.1:5020 --unit-ids 1,2,3 --profile gantry-3d``).

``pacing="virtual"`` runs in lock-step with a simulated drive (1.0 s of the drive's time);
``pacing="wall"`` (the default) keeps the wall clock, as a real drive needs.  The run's
:class:`RunResult` says how it ended (``exit_reason``, ``error``; ``summary`` is None when the
run never cycled, e.g. a drive whose 0x6076 disagrees with the profile's rated torque: a
simulator started without ``--profile`` has its own); ``result.controller`` is the :class:`WallController`.

Names load on first use (PEP 562), so ``import haptic_bus`` is cheap and the analysis never
loads python-can, canopen or pymodbus; the runs (:func:`run`, :func:`run_canopen`, :func:`run_modbus`) and the
drive classes (:class:`CanopenDrive`, :class:`ModbusDrive`) do.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from haptic_bus._version import __version__ as __version__
from haptic_bus.lazy import lazy_getattr

# A library's logging (the logging HOWTO): haptic_bus' records go where the program's logging sends them, and
# nowhere (not logging.lastResort's stderr) in a program that configures none; the command line configures its own.
logging.getLogger(__name__).addHandler(logging.NullHandler())

_HOMES = {
    "check_passivity": "haptic_bus.analysis.check",
    "CheckReport": "haptic_bus.analysis.check",
    "format_check": "haptic_bus.analysis.check",
    "WallLoop": "haptic_bus.analysis.loop",
    "Wall": "haptic_bus.control.scene",
    "Slot": "haptic_bus.control.scene",
    "Detent": "haptic_bus.control.scene",
    "compile_scene": "haptic_bus.control.scene",
    "PassivityGate": "haptic_bus.control.gate",
    "GatePolicy": "haptic_bus.control.gate",
    "GateDecision": "haptic_bus.control.gate",
    "Refusal": "haptic_bus.errors",
    "DeviceLoop": "haptic_bus.analysis.loop",
    "WallController": "haptic_bus.control.controller",
    "RunSummary": "haptic_bus.control.controller",
    "AssumptionBroken": "haptic_bus.errors",
    "SupervisorPolicy": "haptic_bus.control.supervisor",
    "Drive": "drives.base",
    "CanopenDrive": "drives.canopen.drive",
    "ModbusDrive": "drives.modbus.drive",
    "Profile": "haptic_bus.app.profiles",
    "AxesProfile": "haptic_bus.app.profiles",
    "load_profile": "haptic_bus.app.profiles",
    "RunOptions": "haptic_bus.app.run_options",
    "RealtimeSettings": "haptic_bus.app.realtime",
    "run": "haptic_bus.app.runner",
    "RunResult": "haptic_bus.app.runner",
    "run_canopen": "haptic_bus.app.runner",
    "run_modbus": "haptic_bus.app.runner",
    "HapticBusError": "haptic_bus.errors",
    "ParameterError": "haptic_bus.errors",
    "DriveError": "haptic_bus.errors",
}

__all__ = [
    "AssumptionBroken",
    "AxesProfile",
    "CanopenDrive",
    "CheckReport",
    "Detent",
    "DeviceLoop",
    "Drive",
    "DriveError",
    "GateDecision",
    "GatePolicy",
    "HapticBusError",
    "ModbusDrive",
    "ParameterError",
    "PassivityGate",
    "Profile",
    "RealtimeSettings",
    "Refusal",
    "RunOptions",
    "RunResult",
    "RunSummary",
    "Slot",
    "SupervisorPolicy",
    "Wall",
    "WallController",
    "WallLoop",
    "check_passivity",
    "compile_scene",
    "format_check",
    "load_profile",
    "run",
    "run_canopen",
    "run_modbus",
]


__getattr__ = lazy_getattr(__name__, _HOMES, globals())


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


if TYPE_CHECKING:
    from drives.base import Drive
    from drives.canopen.drive import CanopenDrive
    from drives.modbus.drive import ModbusDrive
    from haptic_bus.analysis.check import CheckReport, check_passivity, format_check
    from haptic_bus.analysis.loop import DeviceLoop, WallLoop
    from haptic_bus.app.profiles import AxesProfile, Profile, load_profile
    from haptic_bus.app.realtime import RealtimeSettings
    from haptic_bus.app.run_options import RunOptions
    from haptic_bus.app.runner import RunResult, run, run_canopen, run_modbus
    from haptic_bus.control.controller import RunSummary, WallController
    from haptic_bus.control.gate import GateDecision, GatePolicy, PassivityGate
    from haptic_bus.control.scene import Detent, Slot, Wall, compile_scene
    from haptic_bus.control.supervisor import SupervisorPolicy
    from haptic_bus.errors import AssumptionBroken, DriveError, HapticBusError, ParameterError, Refusal
