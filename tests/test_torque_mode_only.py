"""A mode of operation other than cyclic synchronous torque is said before the drive is asked
anything, connected or not: a CiA-402 mode the master does not drive (7, 8, 9) names CST, as it
does on a connected drive (``tests/test_canopen_master_faults.py``), not "not connected" or
"closed"; ``True`` (1 to ``int()``) is no mode code."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from drives.canopen.drive import CanopenDrive
from drives.cia402_master import Cia402Master
from drives.errors import DriveError, ParameterError
from drives.modbus.drive import ModbusDrive


def _canopen() -> Cia402Master:
    return CanopenDrive(5, interface="virtual", channel="torque-mode-only")


def _modbus() -> Cia402Master:
    return ModbusDrive("127.0.0.1", 15899)  # never connected: nothing needs to listen there


MAKERS = pytest.mark.parametrize("make", [_canopen, _modbus], ids=["canopen", "modbus"])
STATES = pytest.mark.parametrize("closed", [False, True], ids=["not-connected", "closed"])
CALLS = pytest.mark.parametrize("call", ["select_mode", "enable"])


def _drive(make: Callable[[], Cia402Master], closed: bool) -> Cia402Master:
    drive = make()
    if closed:
        drive.close()
    return drive


@MAKERS
@STATES
@CALLS
@pytest.mark.parametrize(("mode", "name"), [(7, "INTERPOLATED_POSITION"), (8, "CYCLIC_SYNCHRONOUS_POSITION"),
                                            (9, "CYCLIC_SYNCHRONOUS_VELOCITY")])
def test_another_cia402_mode_names_cst_before_the_link(make: Callable[[], Cia402Master], closed: bool, call: str,
                                                        mode: int, name: str) -> None:
    drive = _drive(make, closed)
    try:
        with pytest.raises(DriveError, match=rf": this master drives only CYCLIC_SYNCHRONOUS_TORQUE \(10\); {name} "
                                             rf"\({mode}\) was asked$"):
            getattr(drive, call)(mode)
    finally:
        drive.close()


@MAKERS
@STATES
@CALLS
def test_true_is_no_mode_code(make: Callable[[], Cia402Master], closed: bool, call: str) -> None:
    drive = _drive(make, closed)
    try:
        with pytest.raises(ParameterError, match=r"^mode of operation \(0x6060\) = True is invalid; allowed: 1 "):
            getattr(drive, call)(True)
    finally:
        drive.close()
