"""The CiA-402 master over CANopen (canopen + python-can): one drive in cyclic synchronous torque.

The names below load on first use (PEP 562): a process that imports one module of this package
(the simulated drive its local node, an upload client its SDO access) does not import the
master's drive with them (about 0.04 s of CPU, 35 modules, in every ``haptic-bus sim``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drives.canopen.drive import (
        DEFAULT_RPDO,
        DEFAULT_TPDO,
        DEFAULT_TPDO_WITH_POSITION,
        CanopenDrive,
        split_into_frames,
    )
    from drives.canopen.exchange import CanopenStats

_HOMES = {
    "CanopenDrive": "drives.canopen.drive",
    "CanopenStats": "drives.canopen.exchange",
    "DEFAULT_RPDO": "drives.canopen.drive",
    "DEFAULT_TPDO": "drives.canopen.drive",
    "DEFAULT_TPDO_WITH_POSITION": "drives.canopen.drive",
    "split_into_frames": "drives.canopen.drive",
}

__all__ = [
    "CanopenDrive",
    "CanopenStats",
    "DEFAULT_RPDO",
    "DEFAULT_TPDO",
    "DEFAULT_TPDO_WITH_POSITION",
    "split_into_frames",
]


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module 'drives.canopen' has no attribute {name!r}")
    globals()[name] = value = getattr(importlib.import_module(_HOMES[name]), name)
    return value
