"""The simulated drive served over Modbus TCP by pymodbus: :class:`ModbusSimServer`.

pymodbus' own datastore API serves the registers: one :class:`pymodbus.simulator.SimDevice`
spans the whole address space, and its ``action`` callback (awaited by pymodbus for every
holding-register access, with the registers it will answer and the values a write brings)
reads or writes the :class:`~sim_drive.modbus.bank.RegisterBank` and returns the exception code
of the request, if any.  The register semantics and the virtual time are the bank's.

One server may serve several units, each a simulated drive with its own bank (the axes of a
multi-axis device, :mod:`sim_drive.modbus.multi_axis`): :meth:`ModbusSimServer.add_unit`.

Around the bank, per request: a unit id the server does not serve answers 0x0B (gateway target
failed to respond); a function other than the holding-register ones (03, 06, 16, 22, 23) answers
0x01; one armed fault of the :class:`~sim_drive.modbus.faults.FaultInjector` is met (once per
request, so once per FC23, whose write comes before its read).  Two watchdogs stop a unit's
drive when its master is gone, each by the drive's 0x6007 reaction (default: fault, torque
zero) while the power stage is on: the connection that last commanded that unit (wrote its
controlword or target torque) closes (error code 0x8100), or no valid request for the unit
comes from it for the watchdog time of the unit's register 0x002A (error code 0x8130, found at
most :data:`WATCHDOG_TICK` s late: checked when the soonest unit's time can have run out, and
every :data:`WATCHDOG_IDLE` s while none can, since a direct change of a bank or a drive arms none).
"""

from __future__ import annotations

import asyncio
import contextvars
import logging
import math
import threading
import time
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ModbusIOException
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import DataType, SimData, SimDevice
from pymodbus.transaction import TransactionManager

from drives.modbus.in_process import SERVED_HERE, tcp_url
from haptic_bus.errors import ParameterError
from sim_drive.device import POWER_STAGE_ON, SimulatedDrive
from sim_drive.modbus.bank import RegisterBank, writes_command
from sim_drive.modbus.faults import FaultInjector
from sim_drive.operator import OperatorModel
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.sync_clock import SyncClock

logger = logging.getLogger("sim_drive.modbus")

__all__ = ["LINK_LOST_ERROR_CODE", "ModbusSimServer", "ServedUnit", "parse_modbus_url"]

LINK_LOST_ERROR_CODE = 0x8100  # CiA 301 "communication, generic"
WATCHDOG_ERROR_CODE = 0x8130  # CiA 301 "life guard error or heartbeat error"
WATCHDOG_TICK = 0.002  # s
WATCHDOG_IDLE = 0.05  # s: the longest the watchdog sleeps (a request that arms a unit sooner wakes it)
_HOLDING = frozenset({3, 6, 16, 22, 23})  # function codes on holding registers
_ADDRESS_SPACE = 0x10000  # registers 0x0000..0xFFFF: every address reaches the action


@dataclass
class ServedUnit:
    """One unit the server serves: its ``unit_id``, simulated ``drive``, register ``bank``, and the
    connection that last commanded it (``controller``, None until one wrote a command)."""

    unit_id: int
    drive: SimulatedDrive
    bank: RegisterBank
    controller: _Handler | None = None


@dataclass
class _Request:
    """The request being served: its connection, the unit id it names, whether it met its fault."""

    handler: _Handler
    unit: int
    fault_taken: bool = False


# pymodbus serves every request in a task of its own, so each task sees its own request here
_REQUEST: contextvars.ContextVar[_Request] = contextvars.ContextVar("modbus_sim_request")


ACCEPT_GRACE = 0.01  # s: a connection still in the kernel's backlog at the stop is accepted while the server
# can take it; Python 3.11's asyncio accepting one after its server closed fails in the transport's
# constructor and leaks the socket (a ResourceWarning where the garbage collector finds it)

def _wake(future: asyncio.Future[None]) -> None:
    """End the watchdog's sleep (once: its timer and a request may both come)."""
    if not future.done():
        future.set_result(None)


class _Handler(ServerRequestHandler):
    """A client connection: records each request it serves, and reports its closing."""

    def __init__(self, owner: _TcpServer) -> None:
        super().__init__(owner, owner.trace_packet, owner.trace_pdu, owner.trace_connect)
        self.sim = owner.sim
        self._serving: set[asyncio.Task[None]] = set()

    async def handle_request(self) -> None:
        if self.last_pdu is None:
            return
        token = _REQUEST.set(_Request(self, self.last_pdu.dev_id))
        try:
            await super().handle_request()
        finally:
            _REQUEST.reset(token)

    def callback_data(self, data: bytes, addr: tuple[str, int] | None = None) -> int:
        """pymodbus' own, except that the request's task is made at once, not by a callback the loop
        runs on its next turn (one turn of the loop less per request)."""
        try:
            used = TransactionManager.callback_data(self, data, addr)
        except ModbusIOException:  # undecodable: pymodbus' own answers it (the frame parses the same again)
            return super().callback_data(data, addr)
        if self.last_pdu:
            self.handle_later()
        return used

    def handle_later(self) -> None:
        """Serve the request in a task of this loop: pymodbus' own schedules it through
        ``run_coroutine_threadsafe`` from the loop's own thread, a write to the loop's self-pipe and one
        more turn of the loop per request (a loop at 4000 split cycles: 2.8 -> 2.0 s of CPU), for the same
        task in the same order."""
        task = self.loop.create_task(self.handle_request())
        self._serving.add(task)  # the loop holds its tasks weakly
        task.add_done_callback(self._serving.discard)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        if self.is_closing:  # accepted as the server shut down: pymodbus closed it before it had a transport
            transport.close()

    def callback_disconnected(self, exc: Exception | None) -> None:
        super().callback_disconnected(exc)
        self.sim._connection_closed(self)


class _TcpServer(ModbusTcpServer):
    """pymodbus' TCP server with :class:`_Handler` connections."""

    def __init__(self, sim: ModbusSimServer, device: SimDevice, address: tuple[str, int]) -> None:
        super().__init__(device, address=address)
        self.sim = sim

    def callback_new_connection(self) -> _Handler:
        return _Handler(self)


def parse_modbus_url(url: str) -> tuple[str, int]:
    """``tcp://HOST:PORT`` -> (host, port); ParameterError otherwise (port 0 = any free port)."""
    try:
        parsed = urllib.parse.urlsplit(url)
    except ValueError:  # urllib's 'Invalid IPv6 URL': an unclosed '[', a bracket that holds no IPv6 address
        raise ParameterError("--modbus", url, "tcp://HOST:PORT with PORT 0..65535 (0 picks a free port; an IPv6 "
                             "host in brackets, tcp://[::1]:PORT)") from None
    try:
        port = parsed.port
    except ValueError:
        port = None
    if parsed.scheme != "tcp" or not parsed.hostname or port is None or parsed.path not in ("", "/"):
        raise ParameterError("--modbus", url, "tcp://HOST:PORT with PORT 0..65535 (0 picks a free port)")
    return parsed.hostname, port


class ModbusSimServer:
    """The simulated drive served over Modbus TCP (``host``, ``port``; port 0 picks a free one).

    Run it in a background thread (:meth:`start`/:meth:`stop`, or ``with``) or in the caller's
    event loop (:meth:`serve`).  It serves unit ``unit_id`` (and any added with :meth:`add_unit`,
    before it starts): ``units`` by unit id.  ``drive`` is the first unit's :class:`SimulatedDrive`;
    change it (operator, timing) only between cycles.  ``faults`` arms injected faults (any
    unit's requests meet them); ``bank`` holds the first unit's registers.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        unit_id: int = 1,
        timing: Timing | str = Timing.CIA402,
        parameters: DeviceParameters | None = None,
        operator: OperatorModel | None = None,
        word_order: str = "big",
        sync_clock: SyncClock | None = None,
        hand_needs_power: bool = False,
    ) -> None:
        self.host = host
        self.requested_port = port
        self.unit_id = unit_id
        self.word_order = word_order
        self.units: dict[int, ServedUnit] = {}
        self.drive = self.add_unit(unit_id, timing, parameters, operator, sync_clock, hand_needs_power)
        self.bank = self.units[unit_id].bank
        self.faults = FaultInjector()
        self.lock = threading.Lock()  # the banks and the drives, between the server and other threads
        self.port: int | None = None
        self.connections_closed = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._stopped: asyncio.Event | None = None
        self._error: BaseException | None = None
        self._watch_wake: asyncio.Future[None] | None = None  # the watchdog's sleep, until _watch_at (monotonic s)
        self._watch_at = math.inf

    def add_unit(self, unit_id: int, timing: Timing | str = Timing.CIA402, parameters: DeviceParameters | None = None,
                 operator: OperatorModel | None = None, sync_clock: SyncClock | None = None,
                 hand_needs_power: bool = False) -> SimulatedDrive:
        """Serve one more unit ``unit_id`` (0..255, not served yet), a simulated drive of its own with
        ``timing``, ``parameters``, ``operator``, ``sync_clock`` and ``hand_needs_power``
        (:class:`~sim_drive.device.SimulatedDrive`; before :meth:`start`); its drive."""
        if not 0 <= unit_id <= 255 or unit_id in self.units:
            raise ParameterError("unit_id", unit_id, f"0..255, none served already ({sorted(self.units)})")
        drive = SimulatedDrive(parameters, timing, operator, name=f"Modbus unit {unit_id}", hand_needs_power=hand_needs_power)
        self.units[unit_id] = ServedUnit(unit_id, drive, RegisterBank(drive, self.word_order, sync_clock))
        drive.sync()  # SYNC 0: the first sample at t = 0
        return drive

    @property
    def url(self) -> str:
        """``tcp://host:port`` of the bound server."""
        return tcp_url(self.host, self.port)

    # ------------------------------------------------------------------ requests
    def _device(self) -> SimDevice:
        """The pymodbus device: the whole address space, every access through :meth:`_access`.

        Device id 0 is pymodbus' "any unit"; :meth:`_access` refuses the ones that are not ours.
        """
        registers = SimData(0, count=_ADDRESS_SPACE, datatype=DataType.REGISTERS)
        return SimDevice(0, simdata=[registers], action=self._access)

    async def _access(
        self, func_code: int, start_address: int, address: int, count: int,
        registers: list[int], values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """pymodbus' action: read into ``registers`` (``values`` None) or write ``values``; an exception code or None."""
        request = _REQUEST.get()
        unit = self.units.get(request.unit)
        if unit is None:
            return ExcCodes.GATEWAY_NO_RESPONSE
        if func_code not in _HOLDING:
            return ExcCodes.ILLEGAL_FUNCTION
        if not request.fault_taken:
            request.fault_taken = True
            refused = await self._fault(request, func_code)
            if refused is not None:
                return refused
        if values is None:
            with self.lock:
                result = unit.bank.read(address, count)
                if not isinstance(result, int):
                    self._served(unit, request)
            if isinstance(result, int):
                return ExcCodes(result)
            offset = address - start_address
            registers[offset : offset + count] = result
            return None
        with self.lock:
            rc = unit.bank.write(address, values)
            if not rc:
                if writes_command(address, len(values)):
                    unit.controller = request.handler
                self._served(unit, request)
        if rc:
            return ExcCodes(rc)
        return None

    def _served(self, unit: ServedUnit, request: _Request) -> None:
        """A valid request for ``unit`` was answered: its watchdog starts over if it came from the
        connection commanding it (a monitoring client's reads must not keep a drive alive whose
        master is gone); one armed sooner than the watchdog wakes is looked at then."""
        if unit.controller is None or request.handler is unit.controller:
            unit.bank.request_served(time.monotonic())
        wake = self._watch_wake
        if wake is not None and unit.bank.watchdog_deadline() < self._watch_at:
            _wake(wake)

    async def _fault(self, request: _Request, func_code: int) -> ExcCodes | None:
        """Meet the next armed fault, if any: its exception code, after its delay, or the dropped link."""
        fault = self.faults.take()
        if fault is None:
            return None
        if fault.kind == "exception":
            logger.info("%s: injected exception 0x%02X on function %d", self.drive.name, fault.code, func_code)
            return ExcCodes(fault.code)
        if fault.kind == "delay":
            await asyncio.sleep(fault.seconds)
            return None
        logger.info("%s: injected connection drop on function %d", self.drive.name, func_code)
        transport = request.handler.transport
        if isinstance(transport, asyncio.WriteTransport):  # a TCP connection: close it at once
            transport.abort()
        return ExcCodes.DEVICE_FAILURE  # never sent: the connection is gone

    def _connection_closed(self, handler: _Handler) -> None:
        """The communication watchdog: the connection commanding a unit closed."""
        self.connections_closed += 1
        for unit in self.units.values():
            if handler is not unit.controller:
                continue
            unit.controller = None
            with self.lock:
                if unit.drive.state in POWER_STAGE_ON:
                    logger.warning("%s: the commanding connection closed with the power stage on (0x%04X)",
                                   unit.drive.name, LINK_LOST_ERROR_CODE)
                    unit.drive.connection_lost(LINK_LOST_ERROR_CODE)

    async def _watch(self) -> None:
        """The register 0x002A watchdog: at the soonest time a unit's can have run out (at least
        :data:`WATCHDOG_TICK`, at most :data:`WATCHDOG_IDLE` s on), or when a request arms one sooner."""
        loop = asyncio.get_running_loop()
        while True:
            now = time.monotonic()
            with self.lock:
                soonest = min(unit.bank.watchdog_deadline() for unit in self.units.values())
            self._watch_at = now + min(max(soonest - now, WATCHDOG_TICK), WATCHDOG_IDLE)
            self._watch_wake = wake = loop.create_future()
            timer = loop.call_later(self._watch_at - now, _wake, wake)
            try:
                await wake
            finally:
                timer.cancel()
            with self.lock:
                for unit in self.units.values():
                    if unit.bank.watchdog_expired(time.monotonic()):
                        logger.warning("%s: no valid request for %d ms with the power stage on (0x%04X)",
                                       unit.drive.name, unit.bank.watchdog_ms, WATCHDOG_ERROR_CODE)
                        unit.drive.connection_lost(WATCHDOG_ERROR_CODE)

    # ------------------------------------------------------------------ event-loop mode
    async def serve(self, stop: asyncio.Event | None = None, on_bound: Callable[[], None] | None = None) -> None:
        """Serve in the running event loop until ``stop`` is set (or the task is cancelled).

        ``on_bound`` is called once the socket is bound (``port`` is then the real port).
        RuntimeError or OSError if the address cannot be bound.
        """
        self._loop = asyncio.get_running_loop()
        self._stopped = stop or asyncio.Event()
        server = _TcpServer(self, self._device(), (self.host, self.requested_port))
        await server.serve_forever(background=True)
        watchdog = asyncio.create_task(self._watch())
        try:
            sockets = getattr(server.transport, "sockets", None) or []
            self.port = sockets[0].getsockname()[1] if sockets else self.requested_port
            self._ready.set()
            if on_bound is not None:
                on_bound()
            await self._stopped.wait()
        finally:
            watchdog.cancel()
            await asyncio.sleep(ACCEPT_GRACE)  # connections the kernel completed before the stop: accepted now
            await server.shutdown()

    # ------------------------------------------------------------------ thread mode
    def start(self, timeout: float = 5.0) -> ModbusSimServer:
        """Serve in a daemon thread; return once bound within ``timeout`` s (``port`` is then the real port)."""
        if self._thread is not None:
            return self
        self._ready.clear()
        self._thread = threading.Thread(target=self._thread_main, name=f"modbus-sim-{self.unit_id}", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            where = tcp_url(self.host, self.requested_port)
            raise RuntimeError(f"Modbus simulator did not bind {where} within {timeout} s: {self._error}")
        if self._error is not None:
            raise RuntimeError(f"Modbus simulator failed to start: {self._error}") from self._error
        SERVED_HERE.add(self.url)  # a run on it has its drive in this process (drives.modbus.in_process)
        return self

    def _thread_main(self) -> None:
        try:
            asyncio.run(self.serve())
        except BaseException as exc:  # reported by start()
            self._error = exc
            self._ready.set()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the thread started by :meth:`start`, waiting up to ``timeout`` s (idempotent)."""
        thread, loop, stopped = self._thread, self._loop, self._stopped
        if thread is None:
            return
        if loop is not None and stopped is not None and not loop.is_closed():
            loop.call_soon_threadsafe(stopped.set)
        thread.join(timeout)
        self._thread = None
        SERVED_HERE.discard(self.url)

    def __enter__(self) -> ModbusSimServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
