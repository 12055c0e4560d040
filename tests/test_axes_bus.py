"""Several CiA-402 drives on one bus (issue 22): one SYNC per cycle, every axis' TPDOs before any
torque, one safety chain per node, one fate for all axes.

The simulated multi-axis device (one real CANopen slave per axis) and the multi-axis master
(``drives.canopen.axes.CanopenAxes``) share the lock-step bus in this process: each frame is
served in the sender's thread, so the order of frames on the bus is the order they were sent,
and a sniffer (a plain queue receiver on the same channel) sees exactly that order.
"""

from __future__ import annotations

import dataclasses
import pathlib
from collections.abc import Iterator

import can
import numpy as np
import pytest

from drives.canopen.axes import CanopenAxes
from drives.cia301 import SYNC_COB_ID
from drives.cia402 import State
from drives.errors import DriveError, DriveTimeout, ParameterError
from drives.safety import VIRTUAL_TIME_DEADLINE
from haptic_bus.app.profiles import AxesProfile, load_profile
from haptic_bus.app.rig import MultiAxisSim, simulated_axes
from haptic_bus.control.controller import WallController
from haptic_bus.control.joints import encoder_origins
from tests.raw_bus import queued

NODES = (5, 6, 7)
RPDO1 = {node: 0x200 + node for node in NODES}
TPDOS = {cob: node for node in NODES for cob in (0x180 + node, 0x280 + node)}
LOCKSTEP_TPDO_WAIT = 0.05  # s: a cycle's wait for TPDOs the lock-step bus has already served, or never will


def slope_only(tmp_path: pathlib.Path) -> AxesProfile:
    """gantry-3d with the hand pushing straight at the slope (all three axes in contact within 0.5 s)."""
    text = pathlib.Path(load_profile("gantry-3d").path or "").read_text()  # type: ignore[arg-type]
    text = text.replace("toward = [[0.0, -0.03, 0.0], [-0.03, 0.0, 0.0], [0.02, 0.02, 0.01]]", "toward = [0.02, 0.02, 0.01]")
    path = tmp_path / "slope.toml"
    path.write_text(text)
    return load_profile(path)


@pytest.fixture
def rig(tmp_path: pathlib.Path) -> Iterator[tuple[AxesProfile, MultiAxisSim, CanopenAxes, can.BusABC]]:
    """The slope-only gantry on a lock-step bus, the master connected (not enabled), and a sniffer.  The lock-step
    bus serves each frame in its sender's thread: every TPDO that comes is in before the SYNC's send returns, so a
    cycle's wait for TPDOs elapses only for a missed one, and the master waits :data:`LOCKSTEP_TPDO_WAIT` for it, not
    the rig's 0.5 s (each of the three a silent axis misses waited that long)."""
    profile = slope_only(tmp_path)
    with simulated_axes(profile, channel=f"axes-bus-{tmp_path.name}") as (sim, axes):
        axes.cycle.timeout = LOCKSTEP_TPDO_WAIT
        sniffer = can.Bus(interface="lockstep", channel=f"axes-bus-{tmp_path.name}")
        try:
            yield profile, sim, axes, sniffer
        finally:
            sniffer.shutdown()


def controller_for(profile: AxesProfile, axes: CanopenAxes) -> WallController:
    return WallController(axes, profile.gate(), profile.compiled_scene(), names=[a.name for a in profile.axes],
                          force_limit=[a.force_limit for a in profile.axes], origin=encoder_origins(axes),
                          supervisor=profile.supervisor, passivity=profile.passivity)


def test_each_node_has_its_own_safety_chain_written_and_the_sync_is_the_masters(rig) -> None:
    profile, sim, axes, _ = rig
    period_ms = round(profile.period * 1000)
    for drive in axes.drives:
        consumer = int.from_bytes(drive.sdo_read(0x1016, 1), "little")
        floor_ms = round(VIRTUAL_TIME_DEADLINE * 1000)  # a virtual-time rig's watchdogs
        assert consumer >> 16 == 127 and consumer & 0xFFFF == floor_ms  # the controller's one heartbeat, per node
        assert int.from_bytes(drive.sdo_read(0x1400, 5), "little") == max(30, floor_ms // period_ms) * period_ms
        assert int.from_bytes(drive.sdo_read(0x6007, 0), "little", signed=True) == 1  # fault
        assert drive.cycle is axes.cycle and axes.cycle.shared
        with pytest.raises(DriveError, match="shares a SYNC"):
            drive.read_inputs()  # an axis runs no cycle of its own: it never sends a SYNC
    assert [node.drive.state for node in sim.nodes] == [State.SWITCH_ON_DISABLED] * 3
    with pytest.raises(ParameterError, match="distinct node ids"):
        CanopenAxes([5, 5], scalings=[None, None], interface="lockstep", channel="unused")


def test_one_sync_per_cycle_and_every_tpdo_before_any_torque(rig) -> None:
    profile, sim, axes, sniffer = rig
    axes.enable()
    assert [node.drive.state for node in sim.nodes] == [State.OPERATION_ENABLED] * 3
    queued(sniffer)
    controller = controller_for(profile, axes)
    summary = controller.run(300)
    assert summary.exit_reason == "completed" and summary.cycles == 300
    seen = [m for m in queued(sniffer) if m.arbitration_id in (SYNC_COB_ID, *RPDO1.values(), *TPDOS)]
    cycles = []
    for message in seen:
        if message.arbitration_id == SYNC_COB_ID:
            cycles.append([])
        elif cycles:
            cycles[-1].append(message.arbitration_id)
    assert len(cycles) == 300  # one SYNC per cycle, for the three axes
    for ids in cycles:
        tpdos, rpdos = [i for i in ids if i in TPDOS], [i for i in ids if i in RPDO1.values()]
        assert sorted(tpdos) == sorted(TPDOS) and sorted(rpdos) == sorted(RPDO1.values())
        assert max(ids.index(i) for i in tpdos) < min(ids.index(i) for i in rpdos)  # every TPDO before any torque
    # every SYNC served every axis, and each plant heard it: one clock for the device
    assert [drive.stats.syncs_sent for drive in axes.drives] == [node.drive.sync_count for node in sim.nodes]
    assert len({node.drive.sync_count for node in sim.nodes}) == 1


def rpdo_torques(frames: list[can.Message], node: int) -> list[int]:
    """The target torques (0x6071, per mille) of ``node``'s RPDO1 (controlword, torque) among ``frames``."""
    return [int.from_bytes(m.data[2:4], "little", signed=True) for m in frames if m.arbitration_id == RPDO1[node]]


def test_each_axis_target_is_clamped_once_at_its_own_limit_in_the_axes_phase(rig) -> None:
    """In the axes' cyclic phase, a target beyond its axis' limit goes out at that limit, counted
    once in that axis' stats; the other axes' targets go out as asked; the limits end with the phase."""
    _, _, axes, sniffer = rig
    axes.enable()
    with pytest.raises(ParameterError, match="one per axis"):
        with axes.cyclic([100, 100]):
            pass
    queued(sniffer)
    with axes.cyclic([None, 100, 400]) as cycle:
        cycle.read()
        sent = cycle.saturate_and_write([250, -250, -250])
    assert sent == [250, -100, -250]
    assert rpdo_torques(queued(sniffer), 6) == [-100]  # on the wire: the clamped target, once
    assert [d.stats.saturated_outputs for d in axes.drives] == [0, 1, 0]
    assert [d.clamp.limit for d in axes.drives] == [3000, 3000, 3000]  # each drive's own 0x6072 again
    axes.read_inputs()
    axes.write_outputs([0, 3500, 0])  # outside a phase: the drive's own 0x6072
    assert rpdo_torques(queued(sniffer), 6) == [3000]
    assert [d.stats.saturated_outputs for d in axes.drives] == [0, 2, 0]


def test_the_controller_saturates_each_axis_once_through_its_drive(rig) -> None:
    """The y axis' force limit set to 1.5 N (300 per mille) while the hand pushes all three axes onto
    the slope: every cycle that asked more of y sent exactly 300 per mille, counted once in y's
    stats and in the controller's saturated cycles; x and z (12 N) are not clamped."""
    profile, _, axes, sniffer = rig
    limited = dataclasses.replace(profile.axes[1], force_limit=1.5)
    profile = dataclasses.replace(profile, axes=(profile.axes[0], limited, profile.axes[2]))
    axes.enable()
    queued(sniffer)
    controller = controller_for(profile, axes)
    assert controller.torque_limits == [2400, 300, 2400]
    summary = controller.run(600)
    assert summary.exit_reason == "completed"
    newton_per_permille = axes.scalings[1].newton_per_permille
    forces = [controller.records[i].column("force_n") for i in range(3)]
    at_limit = int(np.sum(np.abs(forces[1]) == 300 * newton_per_permille))  # the force asked of y once clamped
    assert at_limit > 100  # y pressed on the slope beyond 1.5 N for most of the run
    assert [d.stats.saturated_outputs for d in axes.drives] == [0, at_limit, 0]
    assert summary.saturated_cycles == at_limit
    assert max(abs(t) for t in rpdo_torques(queued(sniffer), 6)) == 300  # the passivity layer only lowers it
    assert float(np.max(np.abs(forces[0]))) < 12.0 and float(np.max(np.abs(forces[2]))) < 12.0
    assert [d.clamp.limit for d in axes.drives] == [3000, 3000, 3000]


def test_a_missing_tpdo_makes_the_whole_cycle_late(rig) -> None:
    _, sim, axes, _ = rig
    axes.enable()
    for _ in range(5):
        axes.read_inputs()
        axes.write_outputs([0, 0, 0])
    sim.node(6).short_next_tpdo(1)  # node 6's next TPDO1 one byte short: dropped by the master
    inputs = axes.read_inputs()
    assert [i.age for i in inputs] == [0, 1, 0]  # node 6's last input again, one sample old
    assert inputs[1].statusword == axes.drives[1].last_inputs.statusword
    axes.write_outputs([0, 0, 0])
    assert axes.drives[1].stats.missed_tpdos == 1 and axes.drives[1].stats.dropped_frames == 1
    assert [i.age for i in axes.read_inputs()] == [0, 0, 0]


def test_a_tpdo_missing_while_the_state_machines_are_walked_names_its_drive(rig) -> None:
    _, sim, axes, _ = rig
    sim.node(6).short_next_tpdo(1)  # dropped by the master: node 6's TPDOs of the walk's first exchange are not all in
    with pytest.raises(DriveTimeout, match=r"^CANopen node 6: no TPDO within \S+ ms while commanding the state machine$"):
        axes.enable()
    assert [drive.stats.dropped_frames for drive in axes.drives] == [0, 1, 0]


def test_a_silent_axis_zeroes_every_torque_in_the_same_cycle(rig) -> None:
    """Node 6 stops answering while all three axes push on the slope: after its third missed TPDO
    every axis gets zero torque with DISABLE VOLTAGE before one SYNC, and both drives that still
    answer latch zero at that same SYNC; the run ends with a drive error, the record kept."""
    profile, sim, axes, _ = rig
    log: dict[int, list[tuple[int, int, State]]] = {5: [], 7: []}
    for node_id in log:
        drive = sim.node(node_id).drive
        original = drive.sync

        def sync(interval: float | None = None, drive=drive, original=original, node_id=node_id) -> None:
            original(interval)
            log[node_id].append((drive.sync_count, drive.torque_actual, drive.state))

        drive.sync = sync  # type: ignore[method-assign]
    axes.enable()
    controller = controller_for(profile, axes)
    silenced = 400  # cycles: 0.8 s, resting on the slope by then

    def maybe_silence(running: WallController) -> None:
        if running.cycles == silenced:
            sim.node(6).go_silent()

    summary = controller.run(1000, on_cycle=maybe_silence)
    assert summary.exit_reason == "drive error" and "CANopen node 6" in (summary.error or "")
    assert "no TPDO" in (summary.error or "") or "heartbeat" in (summary.error or "")
    assert controller.records[0].total == controller.cycles  # the record is kept, every axis
    assert controller.cycles == silenced + 2  # the third cycle without node 6 raised
    zero_at = {}
    for node_id, entries in log.items():
        pushing = [count for count, torque, _ in entries if torque != 0]
        assert len(pushing) > silenced - 200  # in contact with the slope for most of the run, until the trip
        zero_at[node_id] = pushing[-1] + 1  # the SYNC from which the drive applies zero
        assert entries[-1][0] > zero_at[node_id]
    assert zero_at[5] == zero_at[7]  # the same SYNC
    assert [sim.node(n).drive.state for n in (5, 7)] == [State.SWITCH_ON_DISABLED] * 2
    assert [d.tripped is not None for d in axes.drives] == [True, True, True]
    with pytest.raises(DriveTimeout):
        axes.read_inputs()  # node 6 is still silent: no cycle of its own any more
    sim.node(6).resume()  # the rig's goodbye to node 6 answered (a silent node held each of its SDOs)
