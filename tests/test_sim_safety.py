"""The simulated CANopen drive stops on its own when its master is gone, and keeps serving whatever it receives.

Each test plays the master frame by frame on python-can's virtual bus (or with canopen's own
RemoteNode), so what is checked is the drive's behaviour on the wire: EMCY codes and their
error-register byte against 0x1001, the state after 0x6007's reaction, the torque, and the CiA
301/402 rules the issue listed as deviations.  Waits are bounded (``frames.wait`` per frame).
"""

from __future__ import annotations

import struct
import threading
import time

import can
import canopen
import pytest

from drives.cia402 import Command, State, decode_statusword
from tests.conftest import SDO_WAIT
from tests.raw_bus import FailingBus

NODE = 5
SDO_RX, SDO_TX, EMCY, HEARTBEAT, RPDO1, TPDO1 = 0x600 + NODE, 0x580 + NODE, 0x80 + NODE, 0x700 + NODE, 0x200 + NODE, 0x180 + NODE
MASTER = 0x7F  # the node id the drive's consumer watches in these tests


def emcy_code(message: can.Message) -> int:
    return int(struct.unpack_from("<H", message.data)[0])


def sdo_read(frames, bus: can.BusABC, index: int, subindex: int = 0) -> tuple[int, int]:
    """An expedited upload by hand: (command byte, value) of the answer (value = abort code on abort)."""
    frames.send(bus, SDO_RX, struct.pack("<BHB4x", 0x40, index, subindex))
    answer = frames.recv_id(bus, SDO_TX)
    assert answer is not None, f"no SDO answer reading 0x{index:04X}:{subindex}"
    return answer.data[0], int(struct.unpack_from("<I", answer.data, 4)[0])


def next_emcy(frames, bus: can.BusABC, *, errors_only: bool = True) -> can.Message | None:
    deadline = time.monotonic() + frames.wait
    while (message := frames.recv_id(bus, EMCY, timeout=max(deadline - time.monotonic(), 0.0))) is not None:
        if emcy_code(message) or not errors_only:
            return message
    return None


def sync_statusword(frames, bus: can.BusABC) -> int:
    frames.send(bus, 0x80)
    message = frames.recv_id(bus, TPDO1)
    assert message is not None, "no TPDO after SYNC"
    return int(struct.unpack_from("<H", message.data)[0])


def enabled(frames, master: can.BusABC, torque: int = 400) -> None:
    """NMT start, CST enabled over SDO, one torque through RPDO1 and SYNCs so it acts."""
    frames.nmt_start(master)
    frames.enable_cst(master)
    frames.send(master, RPDO1, struct.pack("<Hh", Command.ENABLE_OPERATION.word, torque))
    for _ in range(2):
        sync_statusword(frames, master)


def test_heartbeat_loss_faults_with_emcy_8130_whose_register_matches_0x1001(sim, master, frames) -> None:
    enabled(frames, master)
    assert sim.drive.torque_actual == 400
    assert frames.sdo_write(master, 0x1016, 1, MASTER << 16 | 40, 4)[0] == 0x60  # 40 ms consumer time
    frames.send(master, 0x700 + MASTER, [0x05])  # the master's first heartbeat arms it ... and then no more
    message = next_emcy(frames, master)
    assert message is not None and emcy_code(message) == 0x8130
    register = message.data[2]
    assert register == 0x11  # generic + communication
    assert sdo_read(frames, master, 0x1001) == (0x4F, register)  # 0x1001 agrees with the EMCY byte
    assert sim.drive.state is State.FAULT and sim.drive.read_object(0x603F) == 0x8130
    assert sim.drive.torque_actual == 0 and decode_statusword(sync_statusword(frames, master)) is State.FAULT


def test_fault_reset_sends_the_error_reset_emcy_and_canopen_clears_its_active_list(sim, master, frames, remote) -> None:
    enabled(frames, master)
    assert frames.sdo_write(master, 0x1016, 1, MASTER << 16 | 30, 4)[0] == 0x60
    frames.send(master, 0x700 + MASTER, [0x05])
    deadline = time.monotonic() + frames.wait
    while not remote.emcy.active and time.monotonic() < deadline:
        time.sleep(0.002)
    assert [e.code for e in remote.emcy.active] == [0x8130]
    frames.drain(master)
    remote.sdo[0x6040].raw = 0x00
    remote.sdo[0x6040].raw = 0x80  # rising edge of bit 7
    reset = next_emcy(frames, master, errors_only=False)
    assert reset is not None and emcy_code(reset) == 0 and reset.data[2] == 0
    deadline = time.monotonic() + frames.wait
    while remote.emcy.active and time.monotonic() < deadline:
        time.sleep(0.002)
    assert remote.emcy.active == [] and remote.sdo[0x1001].raw == 0
    assert sim.drive.state is State.SWITCH_ON_DISABLED


def test_rpdo_deadline_faults_with_emcy_8250(sim, master, frames) -> None:
    assert frames.sdo_write(master, 0x1400, 5, 15, 2)[0] == 0x60  # 15 ms receive deadline
    enabled(frames, master)  # the RPDO arms it; none follows
    message = next_emcy(frames, master)
    assert message is not None and emcy_code(message) == 0x8250 and message.data[2] == 0x11
    assert sim.drive.state is State.FAULT and sim.drive.error_code == 0x8250 and sim.drive.torque_actual == 0


def test_rpdo_deadline_is_not_watched_before_the_first_rpdo(sim, master, frames) -> None:
    assert frames.sdo_write(master, 0x1400, 5, 10, 2)[0] == 0x60
    frames.nmt_start(master)
    frames.enable_cst(master)  # enabled over SDO, no RPDO yet: a master that has not started cycling
    assert frames.recv_id(master, EMCY, timeout=0.05) is None  # five deadlines long
    assert sim.drive.state is State.OPERATION_ENABLED


@pytest.mark.parametrize(("option", "state"),
                         [(2, State.SWITCH_ON_DISABLED), (3, State.SWITCH_ON_DISABLED), (0, State.OPERATION_ENABLED)])
def test_0x6007_decides_what_a_lost_heartbeat_does(sim, master, frames, option, state) -> None:
    assert frames.sdo_write(master, 0x6007, 0, option, 2)[0] == 0x60
    enabled(frames, master)
    assert frames.sdo_write(master, 0x1016, 1, MASTER << 16 | 30, 4)[0] == 0x60
    frames.send(master, 0x700 + MASTER, [0x05])
    message = next_emcy(frames, master)  # the heartbeat event is reported whatever the reaction
    assert message is not None and emcy_code(message) == 0x8130 and message.data[2] == 0x11
    sync_statusword(frames, master)  # a quick stop completes at the next SYNC
    assert sim.drive.state is state
    assert sim.drive.torque_actual == (400 if option == 0 else 0)
    frames.send(master, 0x700 + MASTER, [0x05])  # the master is back: the communication error clears
    reset = next_emcy(frames, master, errors_only=False)
    assert reset is not None and emcy_code(reset) == 0


@pytest.mark.parametrize("command", [0x80, 0x02])  # PRE-OPERATIONAL, STOPPED
def test_nmt_out_of_operational_while_enabled_faults_the_drive(sim, master, frames, command) -> None:
    enabled(frames, master)
    frames.send(master, 0x000, [command, NODE])
    message = next_emcy(frames, master)  # sent while it still was OPERATIONAL
    assert message is not None and emcy_code(message) == 0x8100 and message.data[2] == 0x11
    assert sim.drive.state is State.FAULT and sim.drive.torque_actual == 0
    frames.drain(master)
    sim.send_emcy(0x1000)
    if command == 0x02:
        assert frames.recv_id(master, EMCY, timeout=0.1) is None  # STOPPED: no EMCY at all
    else:
        assert frames.recv_id(master, EMCY) is not None


def test_the_boot_up_counts_as_the_first_heartbeat(channel, master, frames) -> None:
    from sim_drive.canopen.slave import CanopenSimDrive

    with CanopenSimDrive({"interface": "virtual", "channel": channel}, NODE):
        boot = frames.recv_id(master, HEARTBEAT)
        first = frames.recv_id(master, HEARTBEAT)
    assert boot is not None and bytes(boot.data) == b"\x00"
    assert first is not None and bytes(first.data) == b"\x7f"
    gap = first.timestamp - boot.timestamp
    assert 0.09 <= gap <= 0.5  # 0x1017 = 100 ms after the boot-up (the upper bound: a loaded machine)


def test_a_zero_byte_sdo_request_is_dropped_and_the_node_keeps_serving(sim, master, frames) -> None:
    for length in range(0, 8):
        frames.send(master, SDO_RX, bytes(length))
    assert sdo_read(frames, master, 0x1000) == (0x43, 0x00020192)
    assert sim.serving and sim.counters.malformed_frames == 8
    frames.drain(master)
    assert frames.recv_id(master, HEARTBEAT) is not None


def test_a_receive_error_is_counted_and_the_node_keeps_serving(channel, master, frames) -> None:
    from sim_drive.canopen.slave import CanopenSimDrive

    bus = FailingBus(channel, lambda call: call % 7 == 3, "datagram of the wrong length")
    try:
        with CanopenSimDrive(bus, NODE) as sim:
            for _ in range(5):
                assert sdo_read(frames, master, 0x1000)[0] == 0x43
            assert sim.serving and sim.counters.receive_errors >= 1
    finally:
        bus.shutdown()


def test_a_bus_that_keeps_failing_stops_the_heartbeat_and_faults_the_drive(channel, master, frames) -> None:
    from sim_drive.canopen.slave import MAX_RECEIVE_ERRORS_IN_ROW, RECEIVE_FAILURE_TIME, CanopenSimDrive

    dead = threading.Event()
    bus = FailingBus(channel, lambda call: dead.is_set(), "interface gone")
    try:
        sim = CanopenSimDrive(bus, NODE).start()
        assert frames.recv_id(master, HEARTBEAT) is not None
        dead.set()
        deadline = time.monotonic() + RECEIVE_FAILURE_TIME + frames.wait
        while sim.serving and time.monotonic() < deadline:
            time.sleep(0.005)
        assert not sim.serving and sim.counters.receive_errors >= MAX_RECEIVE_ERRORS_IN_ROW
        assert sim.drive.state is State.FAULT
        frames.drain(master)
        assert frames.recv_id(master, HEARTBEAT, timeout=0.3) is None  # it no longer says it is alive
        sim.stop()
    finally:
        bus.shutdown()


@pytest.mark.parametrize(("index", "subindex"), [(0x6041, 1), (0x1017, 5), (0x6060, 2), (0x1000, 1)])
def test_a_subindex_on_a_single_value_object_is_abort_0x06090011(sim, master, frames, index, subindex) -> None:
    assert sdo_read(frames, master, index, subindex) == (0x80, 0x06090011)
    answer = frames.sdo_write(master, index, subindex, 1, 1)
    assert answer[0] == 0x80 and struct.unpack_from("<I", answer, 4)[0] == 0x06090011


def test_a_sync_of_the_wrong_length_is_not_used_and_reported(sim, master, frames) -> None:
    frames.nmt_start(master)
    before = sim.drive.sync_count
    frames.send(master, 0x80, b"\x01\x02")
    message = next_emcy(frames, master)
    assert message is not None and emcy_code(message) == 0x8240 and message.data[2] == 0x11
    assert sim.drive.sync_count == before and frames.recv_id(master, TPDO1, timeout=0.05) is None


@pytest.mark.parametrize("cob_id", [0x000, 0x001, 0x07F, 0x101, 0x585, 0x605, 0x6E0, 0x705, 0x7FF])
def test_restricted_cob_ids_are_refused_for_pdos(sim, master, frames, cob_id) -> None:
    answer = frames.sdo_write(master, 0x1801, 1, 1 << 31 | cob_id, 4)  # TPDO2 is invalid by default
    assert answer[0] == 0x80 and struct.unpack_from("<I", answer, 4)[0] == 0x06090030


def test_emcy_cob_id_changes_only_while_invalid(sim, master, frames) -> None:
    refused = frames.sdo_write(master, 0x1014, 0, 0x90 + NODE, 4)
    assert refused[0] == 0x80 and struct.unpack_from("<I", refused, 4)[0] == 0x06090030
    assert frames.sdo_write(master, 0x1014, 0, 1 << 31 | 0x80 + NODE, 4)[0] == 0x60
    assert frames.sdo_write(master, 0x1014, 0, 1 << 31 | 0x90 + NODE, 4)[0] == 0x60
    assert frames.sdo_write(master, 0x1014, 0, 0x90 + NODE, 4)[0] == 0x60
    sim.send_emcy(0x1000)
    assert frames.recv_id(master, 0x90 + NODE) is not None


def test_cycle_period_zero_reads_back_zero(sim, master, frames) -> None:
    assert frames.sdo_write(master, 0x1006, 0, 0, 4)[0] == 0x60
    assert sdo_read(frames, master, 0x1006) == (0x43, 0)
    assert sim.drive.parameters.period == 1e-3  # the plant keeps its period


def test_unsupported_modes_are_abort_0x06090030(sim, master, frames) -> None:
    for mode in (1, 8, 9):
        answer = frames.sdo_write(master, 0x6060, 0, mode, 1)
        assert answer[0] == 0x80 and struct.unpack_from("<I", answer, 4)[0] == 0x06090030
    assert sdo_read(frames, master, 0x6061) == (0x4F, 0)


def test_statusword_bit_11_shows_a_torque_clamped_at_0x6072(sim, master, frames) -> None:
    enabled(frames, master, torque=3500)  # 0x6072 = 3000
    assert sync_statusword(frames, master) & 1 << 11
    frames.send(master, RPDO1, struct.pack("<Hh", Command.ENABLE_OPERATION.word, 100))
    sync_statusword(frames, master)
    assert not sync_statusword(frames, master) & 1 << 11


def test_reset_node_restores_power_on_values(sim, master, frames, remote) -> None:
    remote.sdo[0x6072].raw = 1200
    remote.sdo[0x6076].raw = 450
    remote.sdo[0x2001][1].raw = 2e-6
    frames.send(master, 0x000, [0x81, NODE])
    assert frames.recv_id(master, HEARTBEAT) is not None  # boot-up
    assert (remote.sdo[0x6072].raw, remote.sdo[0x6076].raw, remote.sdo[0x2001][1].raw) == (3000, 200, 1e-6)


def test_enable_operation_from_ready_to_switch_on_reaches_operation_enabled(sim, master, frames) -> None:
    frames.nmt_start(master)
    assert frames.sdo_write(master, 0x6060, 0, 10, 1)[0] == 0x60
    for word in (Command.SHUTDOWN.word, Command.ENABLE_OPERATION.word):
        assert frames.sdo_write(master, 0x6040, 0, word, 2)[0] == 0x60
    assert sim.drive.state is State.OPERATION_ENABLED


def test_canopen_base_node_402_clears_a_watchdog_fault_with_reset_from_fault(channel, sim) -> None:
    from sim_drive.eds import eds_path

    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    try:
        node = canopen.BaseNode402(NODE, str(eds_path()))
        network.add_node(node)
        node.sdo.RESPONSE_TIMEOUT = SDO_WAIT
        node.sdo[0x6060].raw = 10
        for word in (Command.SHUTDOWN.word, Command.SWITCH_ON.word, Command.ENABLE_OPERATION.word):
            node.sdo[0x6040].raw = word
        node.sdo[0x1016][1].raw = MASTER << 16 | 30
        network.send_message(0x700 + MASTER, [0x05])
        deadline = time.monotonic() + 1.0
        while sim.drive.state is not State.FAULT and time.monotonic() < deadline:
            time.sleep(0.002)
        assert sim.drive.state is State.FAULT and sim.drive.error_code == 0x8130
        node.tpdo.read()  # BaseNode402 reads its statusword from TPDO1
        node.nmt.state = "OPERATIONAL"
        node.sdo[0x1016][1].raw = 0  # the master stops being watched before it resets the fault
        node.reset_from_fault()  # canopen's: out of FAULT and on to OPERATION ENABLED
        assert sim.drive.state is State.OPERATION_ENABLED and sim.drive.error_code == 0
    finally:
        network.disconnect()
