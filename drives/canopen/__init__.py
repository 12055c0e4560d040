"""The CiA-402 master over CANopen (canopen + python-can): one drive in cyclic synchronous torque."""

from drives.canopen.drive import (
    DEFAULT_RPDO,
    DEFAULT_TPDO,
    DEFAULT_TPDO_WITH_POSITION,
    CanopenDrive,
    split_into_frames,
)
from drives.canopen.exchange import CanopenStats

__all__ = [
    "CanopenDrive",
    "CanopenStats",
    "DEFAULT_RPDO",
    "DEFAULT_TPDO",
    "DEFAULT_TPDO_WITH_POSITION",
    "split_into_frames",
]
