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
heartbeat is heard.  On ``modbus`` it is served over Modbus TCP on loopback by a real pymodbus
server in a thread of the test's process (:mod:`sim_drive.modbus`).

A multi-axis profile (``[[axes]]``) is simulated whole, as the profile states it (no truth
replaced): one simulated drive per axis and the profile's hand in space -- on the CAN buses one
slave per axis with the profile's node ids (``python -m sim_drive --node-ids`` in another
process), over Modbus one unit per axis (the profile's unit ids, else 1, 2, 3, ...) on one
server, or on a server each.
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
    from haptic_bus.app.profiles import AxesProfile
    from haptic_bus.app.rig import CanopenSimDrive, ServedUnit
    from haptic_bus.testing.processes import SimProcess

ProfileSource = str | pathlib.Path  # a shipped profile name or a TOML path
# s: a simulator subprocess imports numpy, scipy and canopen before its boot-up (a bound, not a pace: 6.5 s measured
# with four CPU-bound processes beside the test)
HEARTBEAT_WAIT = 60.0
CONTEXT = "simulated drive"
_truth_files = itertools.count(1)


def truth_keys() -> tuple[str, ...]:
    """The ``[device]`` keys a truth may set (every field of the profile's device table but its prose)."""
    from haptic_bus.app.profiles import DeviceTable

    return tuple(f.name for f in dataclasses.fields(DeviceTable) if f.name != "friction_source")


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
    """The simulated drive as CANopen node ``node_id`` on the private bus ``spec`` (several axes:
    ``node_ids``, in axis order), or as Modbus units ``unit_ids`` at ``urls`` (one per axis; ``spec`` None).

    ``truth``: the profile file it runs (None: the simulator's defaults, no operator);
    ``sim``: the simulator object when it runs in this process (one CANopen slave: its ``drive``
    is the simulated hardware, ``position`` m, ``velocity`` m/s, ``state``, ``operator_energy`` J;
    several: :class:`~sim_drive.canopen.multi_axis.MultiAxisSim`; Modbus: the server, or
    :class:`~sim_drive.modbus.multi_axis.MultiAxisModbusSim`), else None; ``process``: the
    ``python -m sim_drive`` subprocess otherwise, else None.
    """

    spec: BusSpec | None
    node_id: int
    truth: pathlib.Path | None
    sim: Any = None
    process: SimProcess | None = None
    stopped: bool = False
    node_ids: tuple[int, ...] = ()
    urls: tuple[str, ...] = ()
    unit_ids: tuple[int, ...] = ()

    @property
    def several(self) -> bool:
        """True for a multi-axis device."""
        return len(self.node_ids) > 1 or len(self.unit_ids) > 1

    @property
    def bus(self) -> Any:
        """What :func:`haptic_bus.run` takes as ``bus``: the CAN bus as python-can keyword arguments,
        or the Modbus URL (a list of them, one per axis, where each axis has its own server)."""
        if self.spec is not None:
            return self.spec.config()
        return self.urls[0] if len(set(self.urls)) == 1 else list(self.urls)

    def run_kwargs(self) -> dict[str, Any]:
        """The keyword arguments of :func:`haptic_bus.run` that name this drive (or these axes)."""
        if self.spec is None:
            return {"unit_ids": list(self.unit_ids)} if self.several else {"unit_id": self.unit_ids[0]}
        return {} if self.several else {"node_id": self.node_id}

    def run_args(self) -> list[str]:
        """The command-line options that reach this drive (``haptic-bus run|status|scan ...``)."""
        if self.spec is None:
            urls = [word for url in dict.fromkeys(self.urls) for word in ("--modbus", url)] if len(set(self.urls)) == 1 \
                else [word for url in self.urls for word in ("--modbus", url)]
            units = ",".join(map(str, self.unit_ids))
            return [*urls, "--unit-ids" if self.several else "--unit-id", units]
        return [*self.spec.sim_args(), *([] if self.several else ["--node-id", str(self.node_id)])]

    def served_units(self) -> list[ServedUnit]:
        """Over Modbus, every axis' served unit (its simulated drive and register bank), in axis order."""
        units = getattr(self.sim, "units", {})
        return list(units.values()) if isinstance(units, dict) else list(units)

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


def start_sim_drive(spec: BusSpec | None, node_id: int, timing: str | None, truth: pathlib.Path | None,
                    start_process: Callable[..., SimProcess], servers: int = 1) -> SimDriveNode:
    """Start the simulated drive of profile file ``truth`` (None: the simulator's defaults) as
    node ``node_id`` on ``spec`` with ``timing`` (None: the profile's, else "cia402"); in this
    process on the in-process interfaces, else through ``start_process`` and its heartbeat.
    ``spec`` None: over Modbus TCP on loopback, unit ``node_id`` (:func:`start_modbus`)."""
    if spec is None:
        return start_modbus(truth, [node_id], servers)
    node = SimDriveNode(spec, node_id, truth)
    if spec.interface in IN_PROCESS:
        node.sim = _in_process(spec, node_id, timing, truth)
        return node
    args = [*node.run_args(), *(["--timing", timing] if timing else []), *(["--profile", str(truth)] if truth else [])]
    node.process = start_process(*args)
    wait_for_heartbeat(spec, node_id, HEARTBEAT_WAIT, node.process)
    return node


def start_axes(spec: BusSpec | None, judged: AxesProfile, start_process: Callable[..., SimProcess],
               servers: int = 1) -> SimDriveNode:
    """Start the simulated device of the multi-axis profile ``judged`` (read from its file, and put through
    its gate here): on ``spec`` one CANopen slave per axis with the profile's node ids (in this process, or
    ``python -m sim_drive --node-ids``), or (``spec`` None) over Modbus, one unit per axis (:func:`start_modbus`)."""
    from haptic_bus.app.profiles import admit

    admit(judged)  # the coupled gate, once
    profile = cast(pathlib.Path, judged.path)  # read from a file
    axes = judged.axes
    if spec is None:
        stated = [axis.unit_id for axis in axes]
        return start_modbus(profile, [u for u in stated if u is not None] if None not in stated
                            else list(range(1, len(axes) + 1)), servers)
    nodes = tuple(cast(int, axis.node_id) for axis in axes)
    node = SimDriveNode(spec, nodes[0], profile, node_ids=nodes)
    if spec.interface in IN_PROCESS:
        from haptic_bus.app.rig import simulated_axes_device

        node.sim = simulated_axes_device(judged, spec.config()).start()
        return node
    node.process = start_process(*spec.sim_args(), "--node-ids", ",".join(map(str, nodes)), "--profile", str(profile))
    for each in nodes:
        wait_for_heartbeat(spec, each, HEARTBEAT_WAIT, node.process)
    return node


def start_modbus(truth: pathlib.Path | None, unit_ids: list[int], servers: int = 1) -> SimDriveNode:
    """The simulated drive of profile file ``truth`` (one axis, or every axis of a multi-axis one;
    None: the simulator's defaults) served over Modbus TCP on loopback in this process, unit
    ``unit_ids[i]`` for axis ``i``, on one server or (``servers`` > 1) one per axis; started (bound)."""
    from haptic_bus.app.rig import ModbusSimServer, MultiAxisModbusSim, read_simulated_device, simulated_modbus

    if truth is None:
        sim: ModbusSimServer | MultiAxisModbusSim = ModbusSimServer(unit_id=unit_ids[0])
    else:
        sim = simulated_modbus(read_simulated_device(truth), unit_ids, servers)
    sim.start()
    urls = sim.urls if isinstance(sim, MultiAxisModbusSim) else (sim.url,)
    return SimDriveNode(None, unit_ids[0], truth, sim=sim, urls=tuple(urls), unit_ids=tuple(unit_ids))


def _in_process(spec: BusSpec, node_id: int, timing: str | None, truth: pathlib.Path | None) -> CanopenSimDrive:
    """The slave in this process, started (boot-up sent, serving): what ``python -m sim_drive --profile
    TRUTH`` serves in another process, read by the same reader."""
    from haptic_bus.app.rig import CanopenSimDrive, read_simulated_device

    config = {"interface": spec.interface, "channel": spec.channel, **spec.extra}
    if truth is None:
        return CanopenSimDrive(config, node_id, timing=timing or "cia402").start()
    axis, operator = read_simulated_device(truth).one_axis()
    return CanopenSimDrive(config, node_id, timing=timing or axis.timing, parameters=axis.parameters,
                           operator=operator).start()
