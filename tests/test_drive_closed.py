"""A drive object used after close() says it is closed, whichever call meets it first.

Before, ``select_mode()``/``enable()``/``state()`` on a closed drive said "not connected; call
connect() first", and ``connect()`` then said "closed": two answers for one state.  No bus is
touched: a drive never connected is closed at once (a CANopen drive on python-can's virtual bus,
a Modbus drive on a port nothing listens on, never dialled)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from drives.base import DriveError
from drives.canopen.drive import CanopenDrive
from drives.cia402 import STATUSWORD
from drives.cia402_master import Cia402Master
from drives.errors import ParameterError
from drives.modbus.axes import ModbusAxes
from drives.modbus.drive import ModbusDrive

CLOSED = "the drive object is closed; create a new one"


def _canopen() -> Cia402Master:
    return CanopenDrive(5, interface="virtual", channel="test_drive_closed")


def _modbus() -> Cia402Master:
    return ModbusDrive("127.0.0.1", 1)


@pytest.mark.parametrize("make", [_canopen, _modbus], ids=["canopen", "modbus"])
@pytest.mark.parametrize("call", ["select_mode", "enable", "connect", "read_object"])
def test_a_closed_drive_says_closed(make: Callable[[], Cia402Master], call: str) -> None:
    drive = make()
    drive.close()
    with pytest.raises(DriveError, match=CLOSED):
        getattr(drive, call)(*([STATUSWORD] if call == "read_object" else []))


def test_closed_axes_say_closed() -> None:
    axes = ModbusAxes([ModbusDrive("127.0.0.1", 1), ModbusDrive("127.0.0.1", 2)])
    axes.close()
    with pytest.raises(DriveError, match="closed; create a new one"):
        axes.enable()


@pytest.fixture(params=[_canopen, _modbus], ids=["canopen", "modbus"])
def unconnected(request: pytest.FixtureRequest) -> Iterator[Cia402Master]:
    """A drive object never connected (no bus touched), closed after the test."""
    drive = request.param()
    yield drive
    drive.close()


def test_a_mode_that_is_none_names_the_codes(unconnected: Cia402Master) -> None:
    with pytest.raises(ParameterError, match=r"mode of operation \(0x6060\) = 99 is invalid; allowed: 1 \(PROFILE_"):
        unconnected.select_mode(99)  # type: ignore[arg-type]  # what an untyped caller passes


def test_a_drive_not_yet_connected_says_connect_first(unconnected: Cia402Master) -> None:
    with pytest.raises(DriveError, match=r"not connected; call connect\(\) first"):
        unconnected.select_mode()
