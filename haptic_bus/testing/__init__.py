"""haptic_bus' pytest plugin: the simulated drive, a running controller and the run's record as fixtures.

Installed with haptic_bus (entry point ``pytest11``, name ``haptic_bus.testing``), so every
test session in that environment has these fixtures; ``pytest -p haptic_bus.testing`` (or
``pytest_plugins = ["haptic_bus.testing"]`` in a top-level ``conftest.py``) loads it where
the package is importable but not installed.  A complete test::

    import pytest

    def test_the_end_stop_holds_a_steady_push(haptic_sim, haptic_controller):
        # the hardware is heavier and more damped than the profile says; a hand pushes 3 N into the wall
        drive = haptic_sim("cia402-handle", mass=1.4, friction=24.0, operator={"model": "constant", "level": 3.0})
        run = haptic_controller("cia402-handle", drive, duration=1.0).wait()  # 1 s of virtual time
        assert run.exit_reason == "completed"
        assert run.record["energy_j"].min() >= 0.0  # the port never gave the hand energy
        depth = run.record["position_m"][-100:].mean() - 0.003  # the wall's surface is 3 mm ahead
        assert depth == pytest.approx(3.0 / 1500.0, rel=1e-3)  # F / K, whatever the mass and friction

SI units throughout: s, m, m/s, N, kg, N/m, N s/m, J; times given to a fixture are seconds
of wall clock when they bound a wait, seconds of virtual time when they say how long a
virtual-time run lasts.  Every fixture is function-scoped: whatever a test started is stopped
at its teardown, and every wait is bounded.

Fixtures
--------

``haptic_sim``
    A factory: ``haptic_sim(profile=None, *, interface="virtual", node_id=5, unit_id=1,
    servers=1, timing=None, operator=None, **truth)`` starts the simulated CiA-402 drive as
    CANopen node ``node_id`` on a bus of its own, or as Modbus unit ``unit_id``
    (``interface="modbus"``), and returns a :class:`SimDriveNode` (``bus``: what
    :func:`haptic_bus.run` takes, the python-can keyword arguments or the Modbus URL;
    ``run_kwargs()``: its keyword arguments that name the drive; ``run_args()``: the command-line
    options that reach it; ``sim``: the simulator object in process; ``process``: the subprocess
    otherwise; ``stop()``).

    - ``interface``: ``"virtual"`` or ``"lockstep"`` (the drive in this process, on
      python-can's virtual bus or the lock-step bus), ``"udp_multicast"`` (``python -m
      sim_drive`` in another process on this host: its own multicast group and UDP port, hop
      limit 0 so no frame leaves the machine), ``"socketcan"`` (``vcan0``; the test is
      skipped, with the reason, where the kernel has no vcan0), or ``"modbus"`` (Modbus TCP on
      loopback, a real pymodbus server in this process on a free port).
    - a multi-axis ``profile`` (``[[axes]]``, e.g. ``"gantry-3d"``): the whole simulated device
      as the profile states it, one simulated drive per axis and its hand in space (no truth
      replaced): on a CAN bus one slave per axis with the profile's node ids; over Modbus one
      unit per axis (the profile's unit ids, else 1, 2, 3, ...) on one server, or on ``servers``
      = one server per axis; ``node_id`` and ``unit_id`` are refused (the profile names them).
    - a one-axis profile: ``node_id`` on a CAN bus, ``unit_id`` over Modbus; the other one is
      refused (it was ignored: ``unit_id=3`` on a CAN bus started node 5).
    - ``profile``: a shipped profile name or a TOML path: the device, loop timing and operator
      the drive simulates (None: the simulator's defaults, nobody holding the handle).
    - ``truth``: the hidden truth, the profile's ``[device]`` values replaced: ``mass`` kg,
      ``friction`` N s/m, ``coulomb_friction`` N, ``velocity_noise`` 0x606C counts rms,
      ``noise_seed``, ``velocity`` (the model of 0x606C), the scaling.  ``operator``: the
      ``[operator_model]`` table, e.g. ``{"model": "constant", "level": 3.0}`` (N), or
      ``{"model": "step", "level": 1.0, "start": 0.1}`` (N, s); see :mod:`sim_drive.operator`.
      The controller is never told: give it the profile it should believe.
    - ``timing``: ``"cia402"``, ``"ideal"`` or ``"reception"`` (None: the profile's).

    A bad value fails at the call, before any bus is opened, with one line naming the field
    and its allowed range.  Teardown stops every drive still running; a subprocess that does
    not exit with status 0 on SIGTERM within 10 s is killed and fails the test.

``haptic_controller``
    A factory: ``haptic_controller(profile, drive, *, duration=1.0, pacing="virtual",
    controller_node_id=127, start_in_contact=None, reset_fault=False, out_dir=None,
    plots=False)`` starts :func:`haptic_bus.run` (what ``haptic-bus run`` runs) in a
    thread against the :class:`SimDriveNode` ``drive`` (one axis or several, CANopen or Modbus)
    and returns a :class:`ControllerRun`.  ``profile``: a shipped name, a TOML path (loaded and
    gated, one axis or ``[[axes]]``) or a :class:`haptic_bus.Profile`;
    ``duration``: s of virtual time (``pacing="wall"``: of wall clock); ``out_dir``: the run's
    folder (None: a fresh temporary one); ``plots``: whether the run draws its pictures (off:
    a test that reads the record needs none, and they cost seconds of CPU a run).
    ``pacing``: ``"virtual"``, lock-step with the simulated drive, or ``"wall"``, each cycle at its
    deadline on the wall clock, as a real drive needs, after the run's pre-flight measures the
    cycle.  Wall pacing needs the drive in a process of its own: against a drive in the test's
    process (``interface`` ``"virtual"``, ``"lockstep"`` or ``"modbus"``) the drive's threads share
    the process and its GIL with the controller, the measured cycles are late, and pre-flight
    refuses the run, rightly (``exit_reason`` ``"refused"``, ``error`` ``... this machine holds T >=
    N ms``).  For wall pacing start the drive as ``python -m sim_drive``:
    ``haptic_sim(profile, interface="udp_multicast")`` (or ``"socketcan"``); over Modbus,
    ``sim_process("--modbus", "tcp://127.0.0.1:0", ...)`` and :func:`haptic_bus.run` against the
    URL it prints.
    ``run.wait(timeout=600)`` lets it end by itself, ``run.stop(timeout=300)`` ends it at the
    next cycle, both return the :class:`RecordedRun` of its folder;
    ``run.wait_cycling(timeout=30)`` blocks until it cycles (the drive, enabled,
    has answered its first cycle).
    Teardown stops every run still going (before the drives stop).

``recorded_run``
    ``recorded_run(folder)``: a run folder (of ``haptic-bus run --out``, ``haptic-bus demo``
    or :func:`haptic_bus.run`) read back as a :class:`RecordedRun`: ``record`` maps each
    ``record.csv`` column (``time_s``, ``position_m``, ``velocity_m_per_s``, ``force_n``,
    ``torque_permille``, ``energy_j``, ...) to a numpy array, one entry per cycle; a multi-axis
    run's ``records`` map each axis' name to its ``record-<axis>.csv`` read the same way;
    ``document`` is ``run.json``; ``exit_reason``, ``error``, ``summary`` and ``events(kind)`` read it.

``bus_spec``
    A factory: ``bus_spec(interface)`` is a :class:`BusSpec` (``interface``, ``channel``,
    ``extra``) no other test shares; ``open()`` a bus handle on it, ``config()`` its keyword
    arguments, ``sim_args()`` its command-line options.  ``"socketcan"`` skips without vcan0.

``sim_process``
    A factory: ``sim_process(*args)`` starts ``python -m sim_drive ARGS`` (any ``haptic-bus
    sim`` command line, Modbus included) and returns a :class:`SimProcess` (``stop(sig,
    timeout)``, ``wait_for_line(text, timeout)``, ``log()``).  Teardown stops every one still
    running: SIGTERM, at most 10 s, then SIGKILL.

Loading this plugin imports only pytest and the standard library; the fixtures import the
bus libraries when a test first uses them.
"""

from __future__ import annotations

import os
import pathlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import pytest

from haptic_bus.testing.buses import INTERFACES, VCAN0_REASON, BusSpec, new_bus_spec, vcan0_exists
from haptic_bus.testing.controller import ControllerRun
from haptic_bus.testing.processes import SimProcess, stop_all
from haptic_bus.testing.run_files import RecordedRun, read_run_folder
from haptic_bus.testing.simulated import CONTEXT, ProfileSource, SimDriveNode, start_axes, start_sim_drive, write_truth

if TYPE_CHECKING:
    from haptic_bus.app.profiles import AxesProfile, Profile

__all__ = [
    "BusSpec",
    "ControllerRun",
    "RecordedRun",
    "SimDriveNode",
    "SimProcess",
    "bus_spec",
    "haptic_controller",
    "haptic_sim",
    "read_run_folder",
    "recorded_run",
    "sim_process",
]

DEFAULT_NODE_ID = 5  # the simulated drive's CANopen node id unless a test names another
DEFAULT_UNIT_ID = 1  # the simulated drive's Modbus unit id unless a test names another
MODBUS = "modbus"  # haptic_sim's interface for Modbus TCP on loopback
DEFAULT_CONTROLLER_NODE_ID = 127  # the controller's own CANopen node id (haptic-bus run's default)


def _private_bus(interface: str) -> BusSpec:
    """A bus of ``interface`` no other test shares; the test skipped where it cannot exist here."""
    if interface not in INTERFACES:
        from haptic_bus.errors import ParameterError

        raise ParameterError("interface", interface, ", ".join((*INTERFACES, MODBUS)), CONTEXT)
    if interface == "socketcan" and not vcan0_exists():
        pytest.skip(VCAN0_REASON)
    return new_bus_spec(interface)


@pytest.fixture
def bus_spec() -> Callable[[str], BusSpec]:
    """``bus_spec(interface)``: a :class:`BusSpec` no other test shares."""
    return _private_bus


@pytest.fixture
def sim_process() -> Iterator[Callable[..., SimProcess]]:
    """``sim_process(*args)``: a started ``python -m sim_drive ARGS``; all stopped at teardown."""
    started: list[SimProcess] = []

    def start(*args: str) -> SimProcess:
        process = SimProcess(*args)
        started.append(process)
        return process

    yield start
    stop_all(started)


@pytest.fixture
def haptic_sim(sim_process: Callable[..., SimProcess],
               tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[..., SimDriveNode]]:
    """``haptic_sim(profile=None, *, interface="virtual", node_id=5, timing=None, operator=None, **truth)``:
    the simulated drive started on a private bus (see the module docstring); all stopped at teardown."""
    started: list[SimDriveNode] = []
    folder: list[pathlib.Path] = []

    def start(profile: ProfileSource | None = None, *, interface: str = "virtual",
              node_id: int | None = None, unit_id: int | None = None, servers: int = 1, timing: str | None = None,
              operator: Mapping[str, Any] | None = None, **truth: Any) -> SimDriveNode:
        from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS
        from haptic_bus.errors import ParameterError
        from haptic_bus.validation import whole_in_range

        several = _axes_profile(profile)
        axes = len(several.axes) if several is not None else 1
        if isinstance(servers, bool) or not isinstance(servers, int) or servers not in (1, axes) or \
                (servers > 1 and interface != MODBUS):
            raise ParameterError("servers", servers, f"1, or one Modbus server per axis ({axes}) with interface="
                                 f"{MODBUS!r}", CONTEXT)
        _refuse_timing_and_operator(timing, operator)
        spec = None if interface == MODBUS else _private_bus(interface)
        if several is not None:
            if truth or operator is not None or timing is not None:
                raise ParameterError("truth", sorted(truth) or operator or timing, "none for a multi-axis profile (it is "
                                     "simulated as it states its [[axes]] and hand)", CONTEXT)
            for name, value in (("node_id", node_id), ("unit_id", unit_id)):
                if value is not None:
                    raise ParameterError(name, value, "none for a multi-axis profile (its [[axes]] name each axis' "
                                         "node and unit ids)", CONTEXT)
            node = start_axes(spec, several, sim_process, servers)
            started.append(node)
            return node
        unused, other, named = ("node_id", node_id, "a Modbus unit: unit_id") if spec is None else \
            ("unit_id", unit_id, "a CANopen node: node_id")
        if other is not None:
            raise ParameterError(unused, other, f"none with interface={interface!r} ({named})", CONTEXT)
        if spec is None and unit_id is not None:  # hb.run's and haptic-bus sim's range (the server's own took 0..255)
            unit_id = whole_in_range("unit_id", unit_id, *UNIT_ID_RANGE, context=CONTEXT, allowed=UNIT_IDS)
        path = None
        if profile is not None:
            if not folder:
                folder.append(tmp_path_factory.mktemp("haptic-sim"))
            path = write_truth(profile, truth, operator, folder[0])
        elif truth or operator is not None:
            raise ParameterError("profile", None, "a shipped profile name or a TOML path when a truth or an operator "
                                                  "is given (the rest of the device comes from it)", CONTEXT)
        address = (DEFAULT_UNIT_ID if unit_id is None else unit_id) if spec is None else \
            (DEFAULT_NODE_ID if node_id is None else node_id)
        node = start_sim_drive(spec, address, timing, path, sim_process, servers)
        started.append(node)
        return node

    yield start
    _each(reversed(started), _stop_cleanly)


def _refuse_timing_and_operator(timing: object, operator: object) -> None:
    """ParameterError for a ``timing`` the simulator has no name for or an ``operator`` that is no table:
    they were the simulator's ValueError ('fast' is not a valid Timing) and dict()'s ("dictionary update
    sequence element #0 has length 1", for the command line's spelling "constant:3")."""
    from haptic_bus.errors import ParameterError
    from haptic_bus.profile.device import TIMINGS  # a profile's [loop] timing: the simulator's own names

    names = list(TIMINGS)
    if timing is not None and timing not in names:
        raise ParameterError("timing", timing, f"one of {', '.join(map(repr, names))}, or None (the profile's)",
                             CONTEXT)
    if operator is not None and not isinstance(operator, Mapping):
        raise ParameterError("operator", operator, "a mapping, the profile's [operator_model] table, e.g. "
                             "{'model': 'constant', 'level': 3.0}", CONTEXT)


def _axes_profile(profile: ProfileSource | None) -> AxesProfile | None:
    """``profile`` read (validated, not judged) if it is a multi-axis one (``[[axes]]``), else None."""
    if profile is None:
        return None
    from haptic_bus.app.profiles import AxesProfile, read_profile

    read = read_profile(profile)
    return read if isinstance(read, AxesProfile) else None


def _stop_cleanly(node: SimDriveNode) -> None:
    """Stop ``node``; a subprocess that does not exit with status 0 on SIGTERM fails the test, and so does
    one that had exited before, unless the test stopped it itself (``drive.process.stop(signal.SIGKILL)``:
    it got the status from that call; teardown said "did not exit cleanly on SIGTERM (status -9)")."""
    process = node.process
    before = None if process is None or node.stopped else process.process.poll()  # exited before teardown
    status = node.stop()
    if status is None or status[0] == 0:
        return
    name = f"simulated drive node {node.node_ids or node.node_id}"
    if before is not None:
        if process is not None and process.sent is not None:
            return  # the test's own stop: its status was the test's to judge
        raise AssertionError(f"{name} had exited before the test's teardown (status {before}; a test that ends it "
                             f"on purpose: drive.process.stop(signal.SIGKILL)): {status[1][-2000:]}")
    raise AssertionError(f"{name} did not exit cleanly on SIGTERM (status {status[0]}): {status[1][-2000:]}")


def _each(items: Iterable[Any], teardown: Callable[[Any], None]) -> None:
    """``teardown`` every item, even after one fails; then fail the test with every failure, one per line."""
    failures = []
    for item in items:
        try:
            teardown(item)
        except (AssertionError, pytest.fail.Exception) as exc:
            failures.append(str(exc))
    if failures:
        pytest.fail("\n".join(failures))


@pytest.fixture
def haptic_controller(haptic_sim: Callable[..., SimDriveNode],
                      tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[..., ControllerRun]]:
    """``haptic_controller(profile, drive, *, duration=1.0, pacing="virtual", controller_node_id=127,
    start_in_contact=None, reset_fault=False, out_dir=None, plots=False)``: ``haptic-bus run`` in a thread
    (see the module docstring; ``pacing="wall"`` needs a drive in a process of its own, e.g.
    ``haptic_sim(..., interface="udp_multicast")``: pre-flight refuses one in the test's process);
    every run still going is stopped at teardown, before the drives."""
    from haptic_bus.app.profiles import AxesProfile, Profile, load_profile
    from haptic_bus.app.run_options import RunOptions, StopRequest

    runs: list[ControllerRun] = []

    def start(profile: ProfileSource | Profile | AxesProfile, drive: SimDriveNode, *, duration: float = 1.0,
              pacing: str = "virtual", controller_node_id: int = DEFAULT_CONTROLLER_NODE_ID,
              start_in_contact: str | None = None, reset_fault: bool = False,
              out_dir: str | os.PathLike[str] | None = None, plots: bool = False) -> ControllerRun:
        believed = profile if isinstance(profile, (Profile, AxesProfile)) else load_profile(profile)
        _refuse_other_axes(believed, drive)
        folder = pathlib.Path(out_dir) if out_dir is not None else tmp_path_factory.mktemp("haptic-run")
        options = RunOptions(duration=duration, pacing=pacing, out_dir=folder, start_in_contact=start_in_contact,
                             live=False, stop=StopRequest(), reset_fault=reset_fault, plots=plots)
        run = ControllerRun(believed, drive, options, controller_node_id)
        runs.append(run)
        return run

    yield start
    _each(reversed(runs), ControllerRun.close)


def _refuse_other_axes(believed: Any, drive: SimDriveNode) -> None:
    """ParameterError when the profile the controller believes has another number of axes than the
    simulated device ``drive`` (hb.run's own refusal named a ``node_id`` the test never gave)."""
    from haptic_bus.app.profiles import AxesProfile
    from haptic_bus.errors import ParameterError

    believed_axes = len(believed.axes) if isinstance(believed, AxesProfile) else 1
    driven_axes = max(len(drive.node_ids), len(drive.unit_ids), 1)
    if believed_axes != driven_axes:
        wanted = "a one-axis profile" if driven_axes == 1 else f"a profile of {driven_axes} [[axes]]"
        raise ParameterError("profile", believed.name, f"{wanted}, as the simulated drive has "
                             f"(this one has {believed_axes} axes)", "haptic_controller")


@pytest.fixture
def recorded_run() -> Callable[[str | os.PathLike[str]], RecordedRun]:
    """``recorded_run(folder)``: a run folder's ``record.csv`` (numpy columns) and ``run.json`` (dict)."""
    return read_run_folder
