"""The Modbus link to one drive: the pymodbus client, its lifecycle, and one request with typed errors.

There is no silent retry or reconnect: requests go out with ``retries=0``, and a dropped
connection or an undecodable answer closes the link until the master reconnects explicitly.
Errors name the drive and what the request was for:

- exception response (0x02 illegal address, 0x03 illegal value, 0x06 busy, ...) ->
  :class:`~drives.errors.DriveRefusal` (``code``, the exception code);
- no answer within ``timeout`` -> :class:`~drives.errors.DriveTimeout`;
- a dropped connection (pymodbus' ``ConnectionException``, or the socket's ``ConnectionError``: a
  reset, a broken pipe; one thing, one word: "connection lost") -> :class:`~drives.errors.ModbusLinkLost`.
"""

from __future__ import annotations

import contextlib
import math
import urllib.parse
from dataclasses import dataclass
from typing import Any

from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.pdu import ModbusPDU
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest, WriteMultipleRegistersRequest, WriteSingleRegisterRequest

from drives.cia402_master import CyclicStats
from drives.errors import DriveError, DriveProtocolError, DriveRefusal, DriveTimeout, ModbusLinkLost, ParameterError
from drives.modbus.in_process import tcp_url
from drives.modbus.register_map import NO_UNIT_CODES, describe_range, exception_name
from drives.ranges import real_in_range


@dataclass(slots=True)
class ModbusStats(CyclicStats):
    """Counters of the Modbus exchange (since construction)."""

    requests: int = 0  # Modbus requests sent (cyclic and acyclic)
    cyclic_requests: int = 0
    exceptions: int = 0  # exception responses
    timeouts: int = 0


@dataclass(frozen=True)
class ModbusAddress:
    """Where the drive is: TCP ``host``/``port``, or RTU on serial device ``port`` with its line settings.

    ``timeout`` (s) is the answer timeout of every request (and the TCP connect timeout).
    """

    host: str | None
    port: int | str
    timeout: float = 0.1
    baudrate: int = 115200
    parity: str = "N"
    stopbits: int = 1
    bytesize: int = 8

    def __post_init__(self) -> None:
        real_in_range("timeout", self.timeout, 0.0, math.inf, low_inclusive=False, unit="s", context="Modbus drive")
        if not self.serial and not (isinstance(self.port, int) and not isinstance(self.port, bool) and 0 < self.port <= 65535):
            raise ParameterError("port", self.port, "a TCP port 1..65535 or a serial device path", "Modbus drive")
        if not self.serial and not self.host:
            raise ParameterError("host", self.host, "a host name or address (Modbus TCP)", "Modbus drive")

    @property
    def serial(self) -> bool:
        """True for RTU over a serial line."""
        return isinstance(self.port, str)

    @property
    def url(self) -> str:
        """``tcp://HOST:PORT`` or ``rtu:/dev/...``."""
        return f"rtu:{self.port}" if self.serial else tcp_url(str(self.host), self.port)

    @classmethod
    def from_url(cls, url: str, timeout: float = 0.1) -> ModbusAddress:
        """``tcp://HOST:PORT`` or ``rtu:/dev/ttyUSB0``; ParameterError naming the URL otherwise."""
        try:
            parsed = urllib.parse.urlsplit(url)
        except ValueError:  # urllib's 'Invalid IPv6 URL': an unclosed '[', a bracket that holds no IPv6 address
            raise ParameterError("url", url, "tcp://HOST:PORT with a port 1..65535 (an IPv6 host in brackets, "
                                 "tcp://[::1]:PORT) or rtu:/dev/SERIAL", "Modbus drive") from None
        if parsed.scheme == "tcp":
            try:
                port = parsed.port
            except ValueError:
                port = None
            if not parsed.hostname or not port or parsed.path not in ("", "/"):
                raise ParameterError("url", url, "tcp://HOST:PORT with a port 1..65535", "Modbus drive")
            return cls(parsed.hostname, port, timeout)
        if parsed.scheme == "rtu" and (parsed.path or parsed.netloc):
            return cls(None, parsed.netloc + parsed.path, timeout)
        raise ParameterError("url", url, "tcp://HOST:PORT or rtu:/dev/SERIAL", "Modbus drive")


class ModbusLink:
    """The pymodbus client to ``address``, opened and closed explicitly; ``send`` one request."""

    def __init__(self, name: str, address: ModbusAddress, stats: ModbusStats) -> None:
        self.name = name
        self.address = address
        self.stats = stats
        self.client: Any = None
        self.up = False
        self._execute: Any = None

    def _make_client(self) -> Any:
        a = self.address
        if a.serial:
            from pymodbus import FramerType
            from pymodbus.client import ModbusSerialClient

            try:
                return ModbusSerialClient(str(a.port), framer=FramerType.RTU, timeout=a.timeout, retries=0,
                                          reconnect_delay=0, baudrate=a.baudrate, parity=a.parity,
                                          stopbits=a.stopbits, bytesize=a.bytesize)
            except RuntimeError as exc:  # pymodbus: "Serial client requires pyserial"
                raise DriveError(self.name, f"cannot open the RTU client: {exc}") from exc
        from pymodbus.client import ModbusTcpClient

        return ModbusTcpClient(str(a.host), port=int(a.port), timeout=a.timeout, retries=0, reconnect_delay=0)

    def open(self) -> None:
        """Connect; DriveTimeout if the drive (or server) cannot be reached in ``timeout``."""
        client = self._make_client()
        if not client.connect():
            client.close()
            raise DriveTimeout(self.name, f"cannot connect within {self.address.timeout:.3g} s "
                                          f"(is the drive/server up, the address right?)")
        self.client = client
        self._execute = client.execute
        self.up = True

    def drop(self) -> None:
        """Close the connection; the link is down until :meth:`open`."""
        self.up = False
        if self.client is not None:
            with contextlib.suppress(OSError, ModbusException):
                self.client.close()

    def send(self, request: ModbusPDU, what: str) -> ModbusPDU:
        """One request (``what`` names it in errors); the answer, or a typed error (module docstring)."""
        if not self.up:
            raise ModbusLinkLost(self.name, f"link is down ({what} not sent) until the master reconnects")
        self.stats.requests += 1
        try:
            response = self._execute(False, request)
        except (ConnectionException, ConnectionError) as exc:  # pymodbus' word for it, or the socket's (ECONNRESET, EPIPE)
            self.drop()
            raise ModbusLinkLost(self.name, f"connection lost while {what}: {exc}; closed until the master reconnects") from exc
        except ModbusIOException as exc:
            self.stats.timeouts += 1
            late = "; the request went out, so a unit that answers late may still apply it" if what.startswith("writing") else ""
            raise DriveTimeout(self.name, f"no answer within {self.address.timeout * 1e3:g} ms while {what} ({exc}){late}") \
                from exc
        except (ModbusException, OSError) as exc:
            self.drop()
            raise DriveProtocolError(self.name, f"bad answer while {what}: {exc}") from exc
        if response.function_code & 0x80:
            self.stats.exceptions += 1
            code = int(getattr(response, "exception_code", 0))
            nobody = f": no unit {request.dev_id} answers at {self.address.url}, check the unit id" \
                if code in NO_UNIT_CODES else ""
            raise DriveRefusal(self.name, f"{what}: exception {exception_name(code)}{nobody}", code)
        return response

    def read_holding(self, unit_id: int, address: int, count: int) -> list[int]:
        """FC03: ``count`` holding registers of unit ``unit_id`` from ``address``; errors name what they map to."""
        what = f"reading {describe_range(address, count)}"
        response = self.send(ReadHoldingRegistersRequest(address=address, count=count, dev_id=unit_id), what)
        registers = list(response.registers)
        if len(registers) != count:
            raise DriveProtocolError(self.name, f"{len(registers)} registers answered while {what}, expected {count}")
        return registers

    def write_holding(self, unit_id: int, address: int, values: list[int]) -> None:
        """FC06 (one register) or FC16 (more) to unit ``unit_id`` from ``address``."""
        what = f"writing {describe_range(address, len(values))}"
        request: ModbusPDU
        if len(values) == 1:
            request = WriteSingleRegisterRequest(address=address, registers=list(values), dev_id=unit_id)
        else:
            request = WriteMultipleRegistersRequest(address=address, registers=list(values), dev_id=unit_id)
            request.count = len(values)
        self.send(request, what)
