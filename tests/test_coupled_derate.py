"""Issue 26: the supervisor's derate for coupled axes, as one axis has it (one search for either
gate, :mod:`haptic_bus.app.derate_table`).

The scene: one plane wall with the normal (1, 1, 0)/sqrt 2, coupling the x and y axes of
gantry-3d, K 6000 N/m and B 5 N s/m.  The coupled gate passes it at the profile's delay of one
sample with a margin of 9.6 N s/m, at 1.5 samples 4.8, at 2 samples it is active (-0.30): a
derate to D = 2 has to scale it down (measured: to 0.874, margin 2.06 >= the policy's 2).  The
table is built in the judge worker (the coupled gate's judgements of a sphere take seconds); a
test waits for it where it must (the worker runs its tasks in order: a task submitted after the
table's is done after them), never a fixed time.
"""

from __future__ import annotations

import json
import pathlib
import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

import numpy as np
import pytest

import haptic_bus as hb
from haptic_bus.app import runner
from haptic_bus.app.derate_table import COUPLED_SCALE_STEPS, DERATE_EXTRA_DELAYS, DerateTable, largest_passing_scale
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.run_options import RunOptions, StopRequest
from haptic_bus.control.space_scene import Plane, SpaceScene, compile_space_scene
from haptic_bus.node.verdicts import judge_pool
from haptic_bus.profile.files import resolve_profile
from sim_drive.modbus.multi_axis import MultiAxisModbusSim
from sim_drive.profile import read_simulated_device
from tests.run_rig import late_clock, wait_until

K, B = 6000.0, 5.0  # N/m, N s/m
GANTRY = resolve_profile("gantry-3d")  # the file only: loading judges every wall (0.8 s at each collection)
TABLE_WAIT = 300.0  # s of wall clock: a bound on a hang of the judge worker, not a pace
PERIOD = 2e-3  # s: gantry-3d's T
LATE = {k: 0.6 * PERIOD for k in range(100, 130)}  # cycles 100..129 0.6 T late: the 11th is cycle 110, D = 1.6 seen


def plane() -> SpaceScene:
    return compile_space_scene([Plane("wall", (0.003, 0.003, 0.0), (-1.0, -1.0, 0.0), K, B)])


def test_the_coupled_table_holds_the_largest_scale_the_gate_passes_at_each_prepared_delay() -> None:
    # built where a run builds it, in the judge worker (one search, not another in this process beside it)
    profile = load_profile("gantry-3d")
    gate, scene = profile.gate(), plane()
    derate = DerateTable(gate, scene, COUPLED_SCALE_STEPS, judge_pool())
    judge_pool().submit(int).result(timeout=TABLE_WAIT)  # after the table's tasks: it is built
    assert all(entry.done() and entry.exception() is None for _, entry in derate.entries)
    assert derate(scene, 1.2) is not None and derate(scene, 1.2)[1].objects == scene.objects  # D = 1.25 passes it whole
    served = derate(scene, 1.6)  # between the prepared 1.5 and 2: served by 2
    assert served is not None
    judge, scaled, decision = served
    assert [loop.delay for loop in judge.axes] == [2.0, 2.0, 2.0]
    assert decision.accepted and decision.worst_margin >= profile.gate_policy.safety_margin
    (wall,) = scaled.objects
    scale = wall.stiffness / K
    assert 0.0 < scale < 1.0 and wall.damping / B == pytest.approx(scale, rel=1e-12)
    assert not judge.passes(scene.scaled(scale + 2.0 ** -COUPLED_SCALE_STEPS))  # the largest, within 2^-8
    assert derate(scene, 1.0 + max(DERATE_EXTRA_DELAYS) + 0.01) is None  # beyond the table


def test_a_table_not_yet_built_says_so_and_is_given_up_whole_at_the_end() -> None:
    # a pool whose one thread is held: the table's five tasks wait behind it, none is built
    profile = load_profile("gantry-3d")
    gate, scene, held = profile.gate(), plane(), threading.Event()
    with ThreadPoolExecutor(max_workers=1) as pool:
        pool.submit(held.wait, TABLE_WAIT)
        derate = DerateTable(gate, scene, COUPLED_SCALE_STEPS, pool)
        assert derate(scene, 1.6) is None
        assert derate.shortfall(1.6) == ("the derate table was not ready: 0 of 5 entries built (the judge worker builds "
                                         "them one after another from the run's start; the coupled gate takes seconds each)")
        longest = 1.0 + max(DERATE_EXTRA_DELAYS)
        assert derate.shortfall(longest + 0.01) == f"beyond the derate table (prepared up to a loop delay of {longest:g} samples)"
        derate.abandon()  # the run's end: every entry still waiting is cancelled, none built after it
        held.set()
    assert derate(scene, 1.2) is None and derate.shortfall(1.2).startswith("the derate table was not ready: 0 of 5")


def test_an_entry_the_judge_worker_is_building_at_the_end_is_given_up_with_the_worker() -> None:
    # gantry-3d's own scene (a sphere: seconds a judgement): at abandon() the worker is building the
    # first entry; it is killed, so every entry fails instead of being built while the process waits
    # to exit (the interpreter's exit joins the executor, which finishes every task it was given)
    profile = load_profile("gantry-3d")
    pool = judge_pool()
    derate = DerateTable(profile.gate(), profile.compiled_scene(), COUPLED_SCALE_STEPS, pool)
    entries = [entry for _, entry in derate.entries]
    assert wait_until(entries[0].running, TABLE_WAIT)  # in the worker: as at a run's end
    derate.abandon()
    wait(entries, timeout=TABLE_WAIT)
    assert all(isinstance(entry.exception(), BrokenProcessPool) for entry in entries)  # none built after the end
    assert judge_pool() is not pool and judge_pool().submit(int).result(timeout=TABLE_WAIT) == 0  # a new worker serves


def derating_profile(tmp_path: pathlib.Path) -> pathlib.Path:
    """gantry-3d with the plane alone, the hand pushing into it, and a supervisor that derates; the
    drives' Modbus watchdog at its longest, 65.5 s: the run's first late cycle waits for the judge
    worker's table (:func:`late_after_the_table`), seconds under load, and the 2 s that virtual time
    gives by default faulted unit 1 (0x8130) beside the suite's load in two of three runs here."""
    text = GANTRY.read_text()
    text = text[:text.index("[space.operator]")]
    path = tmp_path / "derate.toml"
    path.write_text(text + f"""
[supervisor]
on_late = "derate"

[safety]
modbus_watchdog_ms = 65535  # ms: the most the watchdog register (0x002A, 16 bits) holds


[space.operator]
model = "push"
force = 3.0
toward = [0.02, 0.02, 0.0]

[[space.objects]]
kind = "plane"
name = "wall"
point = [0.003, 0.003, 0.0]
normal = [-1.0, -1.0, 0.0]
stiffness = {K}
damping = {B}
""")
    return path


@pytest.fixture
def late_after_the_table(monkeypatch: pytest.MonkeyPatch) -> None:
    """The run's virtual clock reports :data:`LATE`, and its first late cycle waits (bounded) for the
    judge worker to have built the derate table: the alarm finds it, whatever this machine's load."""
    base = late_clock(LATE)

    class TableClock(base):  # type: ignore[misc, valid-type]
        def wait_next(self, cycle: int) -> float:
            if cycle == min(LATE):
                judge_pool().submit(int).result(timeout=TABLE_WAIT)
            return float(super().wait_next(cycle))

    monkeypatch.setattr(runner, "VirtualClock", TableClock)


@pytest.fixture
def modbus_axes(tmp_path: pathlib.Path) -> Iterator[tuple[pathlib.Path, MultiAxisModbusSim]]:
    path = derating_profile(tmp_path)
    device = read_simulated_device(path)
    axes = [(unit, axis.parameters, axis.timing) for unit, axis in zip((1, 2, 3), device.axes)]
    sim = MultiAxisModbusSim([("127.0.0.1", 0)], axes, device.make_hand()).start()
    yield path, sim
    sim.stop()


def test_a_late_three_axis_run_derates_to_the_scene_the_coupled_gate_passes_at_the_observed_delay(
        late_after_the_table: None, tmp_path: pathlib.Path, modbus_axes: tuple[pathlib.Path, MultiAxisModbusSim]) -> None:
    path, sim = modbus_axes
    out = tmp_path / "run"
    options = RunOptions(duration=0.5, pacing="virtual", out_dir=out, live=False, plots=False, stop=StopRequest())
    result = hb.run(load_profile(path), sim.urls[0], options, unit_ids=[1, 2, 3])
    assert result.exit_reason == "completed", result.error
    document = json.loads((out / "run.json").read_text())
    first, derated = document["scenes"]
    assert derated["scene_id"] == 1 and derated["origin"] == "derate to a loop delay of 1.6 samples"
    (wall,) = derated["objects"]
    # the table serves the observed 1.6 samples with its entry for 2 (the first test): that entry alone,
    # built here as the table builds it (the other four cost 0.45 s of CPU and serve no other delay)
    expected = largest_passing_scale(load_profile(path).gate().later(1.0), plane(), COUPLED_SCALE_STEPS)
    assert expected is not None
    assert wall["stiffness"] == expected[1].objects[0].stiffness and wall["damping"] == expected[1].objects[0].damping
    margin = derated["decision"]["worst_margin"]
    assert margin >= 2.0 and first["decision"]["worst_margin"] == pytest.approx(9.613, abs=1e-3)
    kinds = [(event["kind"], event.get("data")) for event in document["events"]]
    assert kinds == [("alarm", {"alarm": "late", "action": "derate"}),
                     ("derate", {"scene_id": 1, "worst_margin": margin})]
    for axis in "xyz":
        scene_id = np.genfromtxt(out / f"record-{axis}.csv", delimiter=",", names=True)["scene_id"]
        assert np.all(scene_id[:111] == 0) and np.all(scene_id[111:] == 1)  # every axis from the same next cycle on
