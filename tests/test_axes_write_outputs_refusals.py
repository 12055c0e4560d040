"""Both multi-axis masters take one cycle outside a cyclic phase alike (``read_inputs``, ``write_outputs``)
and refuse alike, before any frame or request: before ``connect()`` ("not connected"), after
``close()`` ("closed"), and a count of torques other than one per axis is invalid input.  Breaker10:
``CanopenAxes.write_outputs`` tried the safe stop on a bus never opened or released, logged a line per
axis and raised "the bus is closed" (a short list left an axis without its RPDO), and ``ModbusAxes`` had
neither method."""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator

import pytest

from drives.axes_master import AxesMaster
from drives.canopen.axes import CanopenAxes
from drives.cia402 import State, decode_statusword
from drives.errors import DriveError, ParameterError
from drives.modbus.axes import ModbusAxes
from drives.modbus.drive import ModbusDrive
from haptic_bus.app.rig import simulated_modbus
from sim_drive.profile import read_simulated_device


def _canopen() -> AxesMaster:
    return CanopenAxes([5, 6], scalings=[None, None], interface="virtual", channel="axes-write-outputs")


def _modbus() -> AxesMaster:
    return ModbusAxes([ModbusDrive("127.0.0.1", 1502, unit_id=1), ModbusDrive("127.0.0.1", 1502, unit_id=2)])  # never dialled


MASTERS = {"canopen": (_canopen, "CANopen nodes 5, 6"), "modbus": (_modbus, "Modbus units 1, 2 at tcp://127.0.0.1:1502")}


@pytest.fixture(params=list(MASTERS))
def master(request: pytest.FixtureRequest) -> Iterator[tuple[AxesMaster, str]]:
    """A master of two axes never connected, and the name its errors carry; closed after the test."""
    make, name = MASTERS[request.param]
    axes = make()
    yield axes, name
    axes.close()


@pytest.mark.parametrize(("closed", "said"), [(False, "not connected; call connect() first"),
                                              (True, "closed; create a new one")], ids=["new", "closed"])
@pytest.mark.parametrize("call", ["read_inputs", "write_outputs"])
def test_one_cycle_says_the_master_state_and_sends_nothing(master: tuple[AxesMaster, str], call: str, closed: bool,
                                                          said: str, caplog: pytest.LogCaptureFixture) -> None:
    axes, name = master
    if closed:
        axes.close()
    with caplog.at_level(logging.WARNING), pytest.raises(DriveError, match=rf"^{re.escape(name)}: {re.escape(said)}$"):
        getattr(axes, call)(*([[0, 0]] if call == "write_outputs" else []))
    assert caplog.records == []  # no safe stop tried on a bus that is not there


@pytest.mark.parametrize("torques", [[0], [0, 0, 0], []], ids=["short", "long", "empty"])
def test_one_torque_per_axis(master: tuple[AxesMaster, str], torques: list[int]) -> None:
    axes, name = master
    with pytest.raises(ParameterError, match=rf"^{re.escape(name)}: torques = {len(torques)} is invalid; "
                                             r"allowed: one per axis \(2\)$"):
        axes.write_outputs(torques)


def test_modbus_axes_read_and_write_one_cycle_of_every_unit() -> None:
    sim = simulated_modbus(read_simulated_device("gantry-3d"), (1, 2, 3))
    sim.start()
    try:
        axes = ModbusAxes([ModbusDrive.from_url(url, unit_id=unit) for url, unit in zip(sim.urls, (1, 2, 3))])
        with axes:
            axes.connect()
            inputs = axes.read_inputs()
            assert len(inputs) == 3
            assert [decode_statusword(i.statusword) for i in inputs] == [State.SWITCH_ON_DISABLED] * 3
            axes.write_outputs([0, 0, 0])  # zero torque, the drives not enabled: written, nothing moves
            assert [i.velocity for i in axes.read_inputs()] == [0, 0, 0]
    finally:
        sim.stop()
