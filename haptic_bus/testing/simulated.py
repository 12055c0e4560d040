"""The simulated drive on a private bus, with a chosen profile and a hidden truth.

The *truth* is what the simulated hardware is: a profile's ``[device]`` values (``mass`` kg,
``friction`` N s/m, ``coulomb_friction`` N, ``velocity_noise`` 0x606C counts rms,
``noise_seed``, ``velocity``, the scaling) and its ``[operator_model]`` (the hand on the
handle, :mod:`sim_drive.operator`).  The controller is never told it: it runs the profile it is
given, which may say otherwise.  The truth is written as a profile file (the base profile with
the given values replaced) and validated whole before any bus is opened, so a bad value is
one :class:`~haptic_bus.errors.ParameterError` naming the field, its value and its range.

On ``virtual`` and ``lockstep`` the drive runs in the test's process
(:class:`~sim_drive.canopen.slave.CanopenSimDrive`); on ``udp_multicast`` and ``socketcan``
it is ``python -m sim_drive --profile TRUTH_FILE`` in another process, waited for until its
heartbeat is heard.
"""

from __future__ import annotations

import dataclasses
import itertools
import pathlib
from collections.abc import Callable, Mapping, MutableMapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

from haptic_bus.testing.buses import IN_PROCESS, BusSpec, wait_for_heartbeat

if TYPE_CHECKING:
    from haptic_bus.app.rig import CanopenSimDrive
    from haptic_bus.testing.processes import SimProcess

ProfileSource = str | pathlib.Path  # a shipped profile name or a TOML path
# s: a simulator subprocess imports numpy, scipy and canopen before its boot-up (a bound, not a pace: 6.5 s measured
# with four CPU-bound processes beside the test)
HEARTBEAT_WAIT = 60.0
CONTEXT = "simulated drive"
_truth_files = itertools.count(1)


def truth_keys() -> tuple[str, ...]:
    """The ``[device]`` keys a truth may set (every field of the profile's device table but its prose)."""
    from haptic_bus.app.profiles import DeviceProfile

    return tuple(f.name for f in dataclasses.fields(DeviceProfile) if f.name != "friction_source")


def _with_absolute_recording(table: Mapping[str, Any], base: pathlib.Path) -> dict[str, Any]:
    """An operator table whose recording path (``model = "recorded"``), if relative, is made absolute against ``base``."""
    table = dict(table)
    if table.get("model") == "recorded" and isinstance(table.get("path"), str):
        table["path"] = str((base / table["path"]).resolve())
    return table


def write_truth(profile: ProfileSource, truth: Mapping[str, Any], operator: Mapping[str, Any] | None,
                folder: pathlib.Path) -> pathlib.Path:
    """``folder/<name>-truth-N.toml``: profile ``profile`` (a shipped name or a path) with each
    ``[device]`` value of ``truth`` and, if given, the ``[operator_model]`` table ``operator``
    replaced; read back and validated whole (ParameterError naming the field)."""
    import tomlkit

    from haptic_bus.app.profiles import read_profile, resolve_profile

    allowed = truth_keys()
    unknown = sorted(set(truth) - set(allowed))
    if unknown:
        raise _error(f"truth {unknown[0]}", truth[unknown[0]], f"keys of a profile's [device] table: {', '.join(allowed)}")
    source = resolve_profile(profile)
    document = tomlkit.parse(source.read_text())
    device = cast(MutableMapping[str, Any], document["device"])
    for key, value in truth.items():
        device[key] = str(value) if key == "velocity" else value
    if operator is not None:
        document["operator_model"] = _with_absolute_recording(operator, pathlib.Path.cwd())
    elif "operator_model" in document:
        document["operator_model"] = _with_absolute_recording(cast(Mapping[str, Any], document["operator_model"]),
                                                              source.parent)
    path = folder / f"{source.stem}-truth-{next(_truth_files)}.toml"
    path.write_text(tomlkit.dumps(document))
    read_profile(path)  # the whole file valid, or one line naming the field
    return path


def _error(name: str, value: object, allowed: str) -> Exception:
    from haptic_bus.errors import ParameterError

    return ParameterError(name, value, allowed, CONTEXT)


@dataclass
class SimDriveNode:
    """The simulated drive as CANopen node ``node_id`` on the private bus ``spec``.

    ``truth``: the profile file it runs (None: the simulator's defaults, no operator);
    ``sim``: the slave object when it runs in this process (its ``drive`` is the simulated
    hardware: ``position`` m, ``velocity`` m/s, ``state``, ``operator_energy`` J), else None;
    ``process``: the ``python -m sim_drive`` subprocess otherwise, else None.
    """

    spec: BusSpec
    node_id: int
    truth: pathlib.Path | None
    sim: CanopenSimDrive | None = None
    process: SimProcess | None = None
    stopped: bool = False

    @property
    def bus(self) -> dict[str, Any]:
        """The bus as python-can keyword arguments (what :func:`haptic_bus.run_canopen` takes)."""
        return self.spec.config()

    def run_args(self) -> list[str]:
        """The command-line options that reach this drive (``haptic-bus run|status|scan ...``)."""
        return [*self.spec.sim_args(), "--node-id", str(self.node_id)]

    def stop(self) -> tuple[int, str] | None:
        """Stop serving (a subprocess: SIGTERM, bounded wait, SIGKILL and a failed test if it
        hangs); its exit status and log, or None in process.  A second call does nothing."""
        if self.stopped:
            return None
        self.stopped = True
        if self.sim is not None:
            self.sim.stop()
        if self.process is not None:
            return self.process.stop()
        return None


def start_sim_drive(spec: BusSpec, node_id: int, timing: str | None, truth: pathlib.Path | None,
                    start_process: Callable[..., SimProcess]) -> SimDriveNode:
    """Start the simulated drive of profile file ``truth`` (None: the simulator's defaults) as
    node ``node_id`` on ``spec`` with ``timing`` (None: the profile's, else "cia402"); in this
    process on the in-process interfaces, else through ``start_process`` and its heartbeat."""
    node = SimDriveNode(spec, node_id, truth)
    if spec.interface in IN_PROCESS:
        node.sim = _in_process(spec, node_id, timing, truth)
        return node
    args = [*node.run_args(), *(["--timing", timing] if timing else []), *(["--profile", str(truth)] if truth else [])]
    node.process = start_process(*args)
    wait_for_heartbeat(spec, node_id, HEARTBEAT_WAIT, node.process)
    return node


def _in_process(spec: BusSpec, node_id: int, timing: str | None, truth: pathlib.Path | None) -> CanopenSimDrive:
    """The slave in this process, started (boot-up sent, serving)."""
    from haptic_bus.app.profiles import read_profile
    from haptic_bus.app.rig import CanopenSimDrive, DeviceParameters, profile_operator

    config = {"interface": spec.interface, "channel": spec.channel, **spec.extra}
    if truth is None:
        return CanopenSimDrive(config, node_id, timing=timing or "cia402").start()
    profile = read_profile(truth)
    parameters = DeviceParameters(**cast(dict[str, Any], profile.sim_device_parameters()))
    return CanopenSimDrive(config, node_id, timing=timing or profile.loop.timing, parameters=parameters,
                           operator=profile_operator(profile)).start()
