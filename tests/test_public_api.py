"""The public API as documented: ``haptic_bus``'s docstring example runs as written against the
simulated drive, ``run_canopen`` takes an open python-can bus, and every name of ``__all__`` is there."""

from __future__ import annotations

import json
import re

import pytest

import haptic_bus as hb

DOCUMENTED_BUS = '{"interface": "udp_multicast", "channel": "239.74.163.2", "port": 43113}'
DOCUMENTED_OPTIONS = 'hb.RunOptions(duration=1.0, pacing="virtual")'


def docstring_example() -> str:
    """The code block of ``haptic_bus.__doc__`` (the indented lines after its ``::``), dedented."""
    block = hb.__doc__.split("::\n", 1)[1]
    lines = []
    for line in block.splitlines()[1:]:
        if line and not line.startswith("    "):
            break
        lines.append(line[4:])
    return "\n".join(lines)


def test_every_public_name_resolves():
    missing = [name for name in hb.__all__ if getattr(hb, name, None) is None]
    assert missing == []
    for name in ("RunResult", "AssumptionBroken", "SupervisorPolicy", "Drive", "CanopenDrive", "ModbusDrive"):
        assert name in hb.__all__
    assert issubclass(hb.CanopenDrive, hb.Drive) and issubclass(hb.ModbusDrive, hb.Drive)
    assert issubclass(hb.AssumptionBroken, hb.HapticBusError)


def test_one_loader_reads_either_kind_of_profile():
    """``hb.load_profile`` is the one loader: a file without ``[[axes]]`` is a Profile, one with it an
    AxesProfile (its node ids from the file); no second loader beside it."""
    assert isinstance(hb.load_profile("cia402-handle"), hb.Profile)
    three = hb.load_profile("gantry-3d")
    assert isinstance(three, hb.AxesProfile) and [axis.node_id for axis in three.axes] == [5, 6, 7]
    assert not hasattr(hb, "load_any_profile") and "load_any_profile" not in hb.__all__


def test_the_docstring_example_runs_as_written(haptic_sim, recorded_run, tmp_path, monkeypatch):
    """The example, against the simulated drive of the same profile in this process on a lock-step
    bus of this test's own instead of the documented udp_multicast bus (another process, as the
    example's comment starts it, is the two-process tests' to run), and without the run's pictures
    (``plots=False``: nothing here looks at them, about 1 s of CPU; a run's pictures are
    test_run_plots'): the two substitutions."""
    code = docstring_example()
    assert code.count(DOCUMENTED_BUS) == 1 and code.count(DOCUMENTED_OPTIONS) == 1
    drive = haptic_sim("cia402-handle", interface="lockstep", node_id=5)
    monkeypatch.chdir(tmp_path)  # the run's folder: runs/<UTC>-cia402-handle here
    namespace: dict[str, object] = {"__name__": "__main__"}  # run as a script is: its guard's body runs
    code = code.replace(DOCUMENTED_BUS, repr(drive.bus)).replace(DOCUMENTED_OPTIONS, DOCUMENTED_OPTIONS[:-1] + ", plots=False)")
    exec(compile(code, "haptic_bus.__doc__", "exec"), namespace)
    report, result = namespace["report"], namespace["result"]
    assert isinstance(report, hb.CheckReport) and report.passive is False
    assert isinstance(result, hb.RunResult)
    assert (result.exit_reason, result.error) == ("completed", None)
    assert result.summary is not None and result.summary.cycles == 1000  # 1.0 s at T = 1 ms
    assert isinstance(result.controller, hb.WallController)
    assert re.fullmatch(r"\d{8}T\d{6}(\.\d+)?Z?-cia402-handle.*", result.folder.name), result.folder.name
    assert result.folder.parent.resolve() == (tmp_path / "runs").resolve()
    run = recorded_run(result.folder)
    assert run.document["link"]["upload_server"] is True and run.document["status"] == "completed"
    # the profile's hand pushes into the end-stop (K = 1500 N/m, surface 3 mm ahead): it settles at F / K
    steady_force = run.record["force_n"][-100:].mean()
    assert steady_force == pytest.approx(3.0, rel=1e-3)
    assert run.record["position_m"][-100:].mean() - 0.003 == pytest.approx(steady_force / 1500.0, rel=1e-3)


def test_run_canopen_takes_an_open_bus(haptic_sim, tmp_path):
    """An open ``can.BusABC`` (python-can's virtual bus, the drive in this process): the run cycles
    on it, leaves it open for its owner, serves uploads on it, and logs the frames of that one bus handle
    (the drive link's tap)."""
    import can

    drive = haptic_sim("cia402-handle", interface="virtual", node_id=5)
    bus = drive.spec.open()
    try:
        assert isinstance(bus, can.BusABC)
        options = hb.RunOptions(duration=0.5, pacing="virtual", out_dir=tmp_path / "run", live=False, plots=False)
        result = hb.run_canopen(hb.load_profile("cia402-handle"), bus, node_id=5, options=options)
        assert (result.exit_reason, result.error) == ("completed", None)
        assert result.summary is not None and result.summary.cycles == 500
        run = json.loads((result.folder / "run.json").read_text())
        assert run["link"]["upload_server"] is True and run["link"]["bus_log"] is True
        assert run["link"]["bus"]["interface"] == type(bus).__name__
        syncs = sum(frame.arbitration_id == 0x080 for frame in can.LogReader(str(result.folder / "bus.asc")))
        assert syncs >= 500 and run["bus_log"]["frames_lost"] == 0  # one SYNC a cycle (and those of enabling)
        rows = (result.folder / "record.csv").read_text().splitlines()
        assert len(rows) == 1 + 500  # the header and one row a cycle
        bus.send(can.Message(arbitration_id=0x080, is_extended_id=False))  # still open: the caller's to close
    finally:
        bus.shutdown()


def test_an_open_bus_refuses_reset_fault_before_anything_is_written(haptic_sim, tmp_path):
    drive = haptic_sim("cia402-handle", interface="virtual", node_id=5)
    bus = drive.spec.open()
    try:
        options = hb.RunOptions(duration=0.1, pacing="virtual", out_dir=tmp_path / "run", live=False, reset_fault=True)
        with pytest.raises(hb.ParameterError, match=r"reset_fault = True is invalid; allowed: False with an open bus"):
            hb.run_canopen(hb.load_profile("cia402-handle"), bus, node_id=5, options=options)
        assert not (tmp_path / "run").exists()
    finally:
        bus.shutdown()


def test_pacing_is_wall_or_virtual():
    assert hb.RunOptions(duration=1.0).wall_paced
    assert not hb.RunOptions(duration=1.0, pacing="virtual").wall_paced
    with pytest.raises(hb.ParameterError, match=r"pacing = 'realtime' is invalid; allowed: 'wall' or 'virtual'"):
        hb.RunOptions(duration=1.0, pacing="realtime")


@pytest.mark.parametrize(("options", "named"), [({"duration": float("nan")}, "duration = nan"),
                                                ({"duration": -1.0}, "duration = -1.0"),
                                                ({"duration": "1"}, "duration = '1'"),
                                                ({"duration": 1.0, "start_in_contact": "bogus"}, "start_in_contact = 'bogus'"),
                                                ({"duration": 1.0, "scheduling": "bogus"}, "scheduling = 'bogus'"),
                                                ({"duration": 1.0, "pacing": "fast"}, "pacing = 'fast'"),
                                                ({"duration": 1.0, "preflight_cycles": 1}, "preflight_cycles = 1"),
                                                ({"duration": 1.0, "preflight_cycles": 2.5}, "preflight_cycles = 2.5")])
def test_run_options_refuse_what_a_run_cannot_use_before_anything_starts(options: dict, named: str) -> None:
    with pytest.raises(hb.ParameterError, match=f"run options: {re.escape(named)} is invalid; allowed: "):
        hb.RunOptions(**options)


def test_check_passivity_names_each_parameter_as_the_caller_spelled_it() -> None:
    good = {"mass": 1.0, "friction": 20.0, "period": 1e-3, "stiffness": 1500.0, "damping": 10.0}
    for word, bad in (("mass", float("nan")), ("friction", -1.0), ("period", 0.0), ("stiffness", float("inf")),
                      ("damping", -2.0)):
        with pytest.raises(hb.ParameterError, match=f"^{word} = .* is invalid; allowed: a finite real in"):
            hb.check_passivity(**{**good, word: bad})


@pytest.mark.parametrize(("fields", "named"), [({"m": -1.0}, "m = -1.0"), ({"T": float("nan")}, "T = nan"),
                                               ({"delay": -1}, "delay = -1"), ({"velocity": "bogus"}, "velocity = 'bogus'")])
def test_a_device_loop_is_usable_once_it_exists_or_refused_when_built(fields: dict, named: str) -> None:
    from haptic_bus.analysis.loop import DeviceLoop

    with pytest.raises(hb.ParameterError, match=f"^{re.escape(named)} is invalid; allowed: "):
        DeviceLoop(**{"m": 1.0, "b": 20.0, "T": 1e-3, "delay": 1, **fields})


@pytest.mark.parametrize(("bus", "node_id", "named"), [({"interface": "virtual", "channel": "unused"}, True, "node_id = True"),
                                                      ({"interface": "virtual", "channel": "unused"}, 0, "node_id = 0"),
                                                      ({"interface": "virtual", "channel": "unused"}, 128, "node_id = 128"),
                                                      (42, 5, "bus = 42")])
def test_run_canopen_refuses_a_bus_or_node_it_cannot_use_before_anything_starts(bus: object, node_id: object, named: str,
                                                                                tmp_path) -> None:
    options = hb.RunOptions(duration=0.1, pacing="virtual", out_dir=tmp_path / "run")
    with pytest.raises(hb.ParameterError, match=f"^run: {re.escape(named)} is invalid; allowed: "):
        hb.run_canopen(hb.load_profile("cia402-handle"), bus, node_id=node_id, options=options)  # type: ignore[arg-type]
    assert not (tmp_path / "run").exists()


def test_the_readme_shows_the_docstring_example() -> None:
    """The README's Python example is this docstring's, which the test above runs: the same code, line for
    line (the comment lines aside: the docstring's ``\\`` joins its two comment lines into one)."""
    from tests.doc_blocks import README, code_blocks

    def code(text: str) -> list[str]:
        return [line.rstrip() for line in text.strip().splitlines() if not line.lstrip().startswith("#")]

    assert code(code_blocks(README, "python")[0]) == code(docstring_example())


@pytest.mark.parametrize(("interrupted", "reason"), [(True, "interrupted"), (False, "stopped")])
def test_a_stop_asked_before_the_first_cycle_never_enables_the_drive(haptic_sim, tmp_path, interrupted, reason):
    """Ctrl-C (or SIGTERM) during set-up or pre-flight: the run ends as asked with no cycle and the
    drive never enabled -- the check right before enabling (the breaker saw a drive enabled for 10 ms
    after a Ctrl-C in pre-flight)."""
    from drives.cia402 import State
    from haptic_bus.app.run_options import exit_status

    drive = haptic_sim("cia402-handle", interface="lockstep", node_id=5)
    assert drive.sim is not None  # in this process: its state machine is watched directly
    states: list[object] = []
    drive.sim.drive.state_listeners.append(lambda old, new, number: states.append(new))
    options = hb.RunOptions(duration=1.0, pacing="virtual", out_dir=tmp_path / "run", live=False, plots=False)
    options.stop.interrupted = interrupted
    options.stop.event.set()  # as the signal handler does
    result = hb.run_canopen(hb.load_profile("cia402-handle"), drive.bus, node_id=5, options=options)
    assert (result.exit_reason, result.summary) == (reason, None)
    assert exit_status(reason) == (130 if interrupted else 0)
    assert State.OPERATION_ENABLED not in states and drive.sim.drive.state is not State.OPERATION_ENABLED, states
