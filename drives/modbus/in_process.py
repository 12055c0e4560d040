"""The Modbus TCP servers this process serves: a run on one of them has its drive in the control process.

:meth:`sim_drive.modbus.ModbusSimServer.start` (the simulated drive in a thread of this process:
the tests', the pytest plugin's, the demos') adds its ``tcp://host:port`` while it serves, and
:meth:`~sim_drive.modbus.ModbusSimServer.stop` takes it away.  A run whose every URL is here gets
its writer in a thread, as a run on an in-process CAN bus does
(:func:`haptic_bus.app.run_writer.writer_for`): a writer process would cost a second
interpreter's imports and give the cycle nothing, its drive sharing the interpreter lock anyway.
"""

from __future__ import annotations

SERVED_HERE: set[str] = set()  # "tcp://host:port" of each server serving in this process now


def tcp_url(host: str, port: int | str | None) -> str:
    """``tcp://HOST:PORT``, an IPv6 address in brackets (``tcp://[::1]:5020``, as the URL is typed and
    ``urllib.parse`` reads it; ``tcp://::1:5020`` names no port): the one place a Modbus TCP address is
    written, by the master (:attr:`drives.modbus.link.ModbusAddress.url`) and the simulated server alike."""
    return f"tcp://[{host}]:{port}" if ":" in host else f"tcp://{host}:{port}"


def served_here(url: str) -> bool:
    """Whether ``url`` (``tcp://host:port``, as the server states it) is served by this process now."""
    return url in SERVED_HERE
