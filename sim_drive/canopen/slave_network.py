"""canopen's Network as a simulated slave uses it: its sends honour the slave's silence and feed its bus
meter, and canopen's own periodic heartbeat task is never started (the slave's receive thread sends it)."""

from __future__ import annotations

import threading
from typing import Any, Protocol

import can
import canopen


class Slave(Protocol):
    """What the network asks of its slave (:class:`~sim_drive.canopen.slave.CanopenSimDrive`)."""

    @property
    def silent(self) -> bool:
        """Whether the slave sends nothing now."""
        ...

    def meter_frame(self, data_bytes: int) -> None:
        """Count one frame of ``data_bytes`` data bytes on the bus meter."""
        ...


class _NoPeriodicTask:
    """What canopen's NmtSlave gets for its periodic heartbeat: nothing (the slave produces its own)."""

    def stop(self) -> None:
        """Nothing runs."""

    def update(self, data: object) -> None:
        """Nothing runs."""


class SlaveNetwork(canopen.Network):
    """canopen's Network adapted to the slave: sends honour its silence and feed its bus meter,
    and canopen's own periodic heartbeat task is never started (the receive thread sends it)."""

    def __init__(self, bus: can.BusABC, slave: Slave) -> None:
        super().__init__(bus)
        self._slave = slave
        # Re-entrant (drives.lockstep_bus): a heartbeat sent under it may deliver the master's SYNC
        # to this node, whose TPDO is then sent inside that send; a plain Lock deadlocked there.
        self.send_lock = threading.RLock()  # type: ignore[assignment]

    def send_message(self, can_id: int, data: bytes | bytearray | list[int], remote: bool = False) -> None:
        """Send unless the slave is silent."""
        if self._slave.silent:
            return
        self._slave.meter_frame(len(data))
        super().send_message(can_id, bytes(data), remote)

    def send_periodic(self, can_id: int, data: Any, period: float, remote: bool = False) -> Any:
        """canopen's NmtSlave asks for a periodic heartbeat on a 0x1017 write: the slave's own thread does it."""
        return _NoPeriodicTask()
