"""An independent client, canopen's own ``BaseNode402`` with the shipped EDS, commissions the drive.

One scenario, three buses: python-can ``virtual`` (simulated drive in this process),
``udp_multicast`` on the loopback host (``python -m sim_drive`` as a subprocess, a unique
group and port per test, stopped with SIGTERM), and SocketCAN ``vcan0`` where the kernel has it.

canopen 2.4.1 quirks worked around here (the drive is not bent to them):

- ``BaseNode402.setup_pdos`` asserts ``self.nmt.state in 'PRE-OPERATIONAL', 'OPERATIONAL'``,
  a substring test on one string: it passes only for PRE-OPERATIONAL (and OPERATIONAL, as a
  substring), so the master must have heard a heartbeat before calling it.
- ``BaseNode402.op_mode = ...`` swallows its own timeout (RuntimeError) and only logs a
  warning, so the test reads the mode back.
- ``BaseNode402.controlword`` sends an RPDO only if it is not "periodic", and treats every
  transmission type <= 240 as periodic; with a synchronous RPDO the controlword would never
  leave unless the test ran ``rpdo.start()``.  The EDS default RPDO1 type 255 avoids that.
- ``PdoMap.read()`` subscribes the master's own RPDOs for reception, and ``on_message`` sets
  ``PdoMap.period`` from the gap between two received frames.  On an interface that echoes
  a sender's own frames (``udp_multicast``) the second echo makes the RPDO "periodic", and
  from then on ``BaseNode402`` silently stops sending controlwords.  The test unsubscribes
  the RPDOs after setup.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from typing import Any

import canopen
import pytest

from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.eds import eds_path

NODE = 7
BOOT_WAIT = 20.0  # s: a subprocess imports numpy, canopen, python-can before it boots
SYNC_PERIOD = 0.002  # s

INTERFACES = [
    pytest.param("virtual", id="virtual-in-process"),
    pytest.param("udp_multicast", id="udp_multicast-subprocess"),
    pytest.param(
        "socketcan",
        id="vcan0-subprocess",
        marks=pytest.mark.vcan0,
    ),
]


@contextlib.contextmanager
def simulated_drive(
    interface: str, channel: str, multicast: tuple[str, int], sim_process: Callable[..., Any]
) -> Iterator[tuple[dict[str, Any], list[str], Callable[[], object]]]:
    """Yield the master's bus kwargs, a list filled with the drive's log lines on exit, and its start.

    ``channel``, ``multicast`` and ``sim_process`` are the fixtures of conftest.py."""
    log: list[str] = []
    if interface == "virtual":
        config = {"interface": "virtual", "channel": channel}
        drive = CanopenSimDrive(config, NODE)
        yield config, log, drive.start
        drive.stop()
        return
    if interface == "udp_multicast":
        group, port = multicast
        config = {"interface": "udp_multicast", "channel": group, "port": port}
        extra = ["--bus-option", f"port={port}"]
    else:
        config = {"interface": "socketcan", "channel": "vcan0"}
        extra = []
    process: list[Any] = []
    args = ["--interface", interface, "--channel", config["channel"], "--node-id", str(NODE), *extra]
    yield config, log, lambda: process.append(sim_process(*args))
    status, text = process[0].stop()
    assert status == 0, text
    log.extend(text.splitlines())


@pytest.mark.parametrize("interface", INTERFACES)
def test_base_node_402_commissions_the_simulated_drive(
    interface: str, channel: str, multicast: tuple[str, int], sim_process: Callable[..., Any]
) -> None:
    with simulated_drive(interface, channel, multicast, sim_process) as (config, log_lines, start):
        network = canopen.Network()
        node = canopen.BaseNode402(NODE, str(eds_path()))
        network.add_node(node)
        network.connect(**config)
        try:
            start()
            node.nmt.wait_for_heartbeat(BOOT_WAIT)
            assert node.nmt.state == "PRE-OPERATIONAL"
            commission(node, network)
        finally:
            network.disconnect()
    if interface != "virtual":  # the subprocess logged one line per state change, then exited 0
        changes = [line for line in log_lines if "(transition" in line]
        assert any("SWITCHED ON -> OPERATION ENABLED (transition 4)" in line for line in changes), log_lines
        assert any("OPERATION ENABLED -> SWITCH ON DISABLED (transition 9)" in line for line in changes), log_lines


def commission(node: canopen.BaseNode402, network: canopen.Network) -> None:
    """Remap TPDO1 over SDO, walk to OPERATION ENABLED in CST, push, read TPDOs, walk back."""
    node.tpdo.read()
    tpdo = node.tpdo[1]
    tpdo.clear()
    tpdo.add_variable(0x6041)
    tpdo.add_variable(0x606C)
    tpdo.trans_type = 1
    tpdo.enabled = True
    tpdo.save()
    node.setup_402_state_machine(read_pdos=True)
    for rpdo in node.rpdo.values():
        if rpdo.enabled:
            network.unsubscribe(rpdo.cob_id, rpdo.on_message)  # see the module docstring
    assert [v.index for v in node.tpdo[1].map] == [0x6041, 0x606C]
    node.nmt.state = "OPERATIONAL"
    network.sync.start(SYNC_PERIOD)
    try:
        node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
        assert node.op_mode == "CYCLIC SYNCHRONOUS TORQUE"
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        node.rpdo[1]["Target torque"].raw = 100  # 1 N at the handle
        node.rpdo[1].transmit()
        velocity = 0
        deadline = time.monotonic() + 2.0
        while velocity <= 0 and time.monotonic() < deadline:
            assert tpdo.wait_for_reception(timeout=1.0) is not None
            velocity = tpdo["Velocity actual value"].raw
        assert velocity > 0  # counts of 1 um/s: the handle accelerates under the pushed torque
        node.state = "SWITCH ON DISABLED"
        assert node.state == "SWITCH ON DISABLED"
    finally:
        network.sync.stop()
