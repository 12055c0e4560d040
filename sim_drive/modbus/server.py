"""The simulated CiA-402 drive as a real pymodbus TCP server (register map: :mod:`drives.modbus.register_map`).

    haptic-bus sim --modbus tcp://127.0.0.1:PORT [--timing cia402|ideal] [--profile P]
                   [--unit-id N] [--word-order big|little] [--realtime]
    python -m sim_drive --modbus tcp://127.0.0.1:PORT ...

The drive behind the registers is :class:`sim_drive.device.SimulatedDrive`, the same plant,
state machine and operator models as the CANopen slave; this module only maps registers onto
its objects (:class:`RegisterBank`) and serves them (:class:`ModbusSimServer`).

Virtual time.  Modbus has no SYNC; the controller's write of the output block stands for it.
At start the server takes the first sample (SYNC 0, t = 0).  A write request that covers the
whole output block 0x0010..0x0011 (FC16 of the block, or the write half of an FC23) applies
its registers in address order (controlword, then target torque) and then runs one
:meth:`SimulatedDrive.sync`: the plant advances by exactly ``T`` and the inputs are
sampled.  So the write of cycle k is SYNC k+1 of the CANopen simulator with the RPDO of cycle
k applied just before it, and both timings keep their meaning: ``ideal``, the torque written
in answer to sample k acts during [t_k, t_k+1); ``cia402``, it is latched at that SYNC and
acts one period later.  Reads never advance time; a write of the controlword or the target torque alone (FC06)
acts at once without advancing the plant (acyclic commissioning: the state machine walk).
An FC23 writes first and reads afterwards (Modbus order), so its read returns the new sample.
The wall clock paces nothing; ``--realtime`` only timestamps the log lines.

Exceptions: 0x02 for unmapped or read-only registers and for partial access to a multi-
register value, 0x03 for a value outside the object's range (nothing of the request is
applied), 0x0B for a unit id other than the server's.  :class:`FaultInjector` makes the next
requests answer "server busy" (0x06) or any other exception, answer late, or drop the
connection.  When the connection that last commanded the drive closes while it is in
OPERATION ENABLED, the drive faults with error code 0x8100 (communication) and removes the
torque, as a drive's communication watchdog does.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
import threading
import time
import urllib.parse
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import NoSuchIdException
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler

from drives.cia402 import State
from drives.modbus.register_map import (
    INPUT_BLOCK,
    INPUT_BLOCK_COUNT,
    MAP_IDENTITY,
    OUTPUT_BLOCK,
    OUTPUT_BLOCK_COUNT,
    REGISTER_BY_NAME,
    REGISTERS,
    SIM_TIMING_CODES,
    InputBlockCodec,
    RegisterSpec,
    encode_value,
    register_at,
)
from drives.errors import ParameterError
from sim_drive.device import ObjectAccessError, SimulatedDrive
from sim_drive.operator import OperatorModel
from sim_drive.parameters import DeviceParameters, Timing

logger = logging.getLogger("sim_drive.modbus")

__all__ = ["RegisterBank", "FaultInjector", "ModbusSimServer", "parse_modbus_url", "main", "LINK_LOST_ERROR_CODE"]

LINK_LOST_ERROR_CODE = 0x8100  # CiA 301 "communication, generic"
TORQUE_REGISTER = REGISTER_BY_NAME["target_torque"].address
CONTROLWORD_REGISTER = REGISTER_BY_NAME["controlword"].address
_HOLDING = frozenset({3, 6, 16, 22, 23})


class RegisterBank:
    """Register reads and writes against a :class:`SimulatedDrive` (no network here).

    ``read(address, count)`` returns the registers or an exception code (int);
    ``write(address, values)`` returns 0 or an exception code.  See the module docstring for
    when a write closes a cycle.
    """

    def __init__(self, drive: SimulatedDrive, word_order: str = "big") -> None:
        self.drive = drive
        self.word_order = word_order
        self.cycles = 0  # writes that closed a cycle
        self._inputs = InputBlockCodec(word_order, with_position=True)
        identity = REGISTER_BY_NAME["map_identity"]
        # read: value source per register spec
        self._sources: dict[RegisterSpec, Any] = {}
        for spec in REGISTERS:
            if spec.obj is not None:
                self._sources[spec] = drive.reader(spec.obj.index)
        self._sources[identity] = lambda: MAP_IDENTITY
        self._sources[REGISTER_BY_NAME["velocity_per_count"]] = lambda: drive.parameters.velocity_per_count
        self._sources[REGISTER_BY_NAME["position_per_count"]] = lambda: drive.parameters.position_per_count
        self._sources[REGISTER_BY_NAME["force_per_torque"]] = lambda: drive.parameters.force_per_torque
        self._sources[REGISTER_BY_NAME["sim_timing"]] = lambda: SIM_TIMING_CODES[drive.timing.value]
        self._sources[REGISTER_BY_NAME["sim_cycle_count"]] = lambda: drive.sync_count & 0xFFFFFFFF
        self._sources[REGISTER_BY_NAME["sim_time"]] = lambda: drive.time
        self._sources[REGISTER_BY_NAME["sim_operator_energy"]] = lambda: drive.operator_energy
        self._sources[REGISTER_BY_NAME["sim_wall_energy"]] = lambda: drive.wall_energy
        writable = drive.writable_objects()
        self._writable = {spec for spec in REGISTERS if spec.obj is not None and spec.access == "rw" and spec.obj.index in writable}

    # ------------------------------------------------------------------ reads
    def read(self, address: int, count: int) -> list[int] | int:
        """``count`` registers from ``address``, or 0x02 if any is unmapped or a value is cut."""
        drive = self.drive
        if address == INPUT_BLOCK and 1 <= count <= INPUT_BLOCK_COUNT and count != 2 and count != 4:
            return self._inputs.encode(drive.statusword, drive.velocity_counts, drive.position_counts)[:count]
        out: list[int] = []
        end = address + count
        a = address
        while a < end:
            spec = register_at(a)
            if spec is None or spec.address != a or spec.end > end:
                return ExcCodes.ILLEGAL_ADDRESS
            out += encode_value(spec, self._sources[spec](), self.word_order)
            a = spec.end
        return out

    # ------------------------------------------------------------------ writes
    def write(self, address: int, values: Sequence[int]) -> int:
        """Write ``values`` from ``address``; 0, or 0x02/0x03 with nothing applied."""
        end = address + len(values)
        decoded: list[tuple[RegisterSpec, int]] = []
        a = address
        while a < end:
            spec = register_at(a)
            if spec is None or spec.address != a or spec.end > end or spec not in self._writable:
                return ExcCodes.ILLEGAL_ADDRESS
            words = values[a - address : spec.end - address]
            if any(not 0 <= w <= 0xFFFF for w in words):
                return ExcCodes.ILLEGAL_VALUE
            value = _decode_int(spec, words, self.word_order)
            if value is None:
                return ExcCodes.ILLEGAL_VALUE
            decoded.append((spec, value))
            a = spec.end
        drive = self.drive
        for spec, value in decoded:
            if spec.obj.index == 0x605A and not 0 <= value <= 8:
                return ExcCodes.ILLEGAL_VALUE  # checked before anything is applied
        for spec, value in decoded:
            try:
                drive.write_object(spec.obj.index, value)
            except ObjectAccessError as exc:
                logger.warning("%s: write of %s refused: %s", drive.name, spec.label, exc)
                return ExcCodes.ILLEGAL_VALUE if exc.reason == "range" else ExcCodes.ILLEGAL_ADDRESS
        if address <= OUTPUT_BLOCK and end >= OUTPUT_BLOCK + OUTPUT_BLOCK_COUNT:
            drive.sync()
            self.cycles += 1
        return 0


def _decode_int(spec: RegisterSpec, words: Sequence[int], word_order: str) -> int | None:
    """The integer ``words`` carry for ``spec``, or None if outside its range (e.g. INTEGER8)."""
    if spec.count == 1:
        raw = words[0]
    else:
        hi, lo = (words[0], words[1]) if word_order == "big" else (words[1], words[0])
        raw = hi << 16 | lo
    bits = 16 * spec.count
    if spec.kind in ("i16", "i8", "i32") and raw >= 1 << (bits - 1):
        raw -= 1 << bits
    low, high = spec.range
    return raw if low <= raw <= high else None


@dataclass
class _Fault:
    kind: str  # "exception", "delay", "drop"
    count: int
    code: int = 0
    seconds: float = 0.0


class FaultInjector:
    """Faults for the next requests, consumed one per request (thread-safe to arm).

    ``busy(n)``: answer 0x06 SERVER DEVICE BUSY; ``exception(code, n)``: any exception code;
    ``delay(seconds, n)``: answer late; ``drop()``: close the connection instead of answering.
    Nothing of a faulted request is applied (a delayed one is applied after the delay).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._queue: list[_Fault] = []
        self.injected = 0

    def busy(self, count: int = 1) -> None:
        """The next ``count`` requests answer exception 0x06 (server busy)."""
        self.exception(ExcCodes.DEVICE_BUSY, count)

    def exception(self, code: int, count: int = 1) -> None:
        """The next ``count`` requests answer exception ``code``."""
        with self._lock:
            self._queue.append(_Fault("exception", count, code=int(code)))

    def delay(self, seconds: float, count: int = 1) -> None:
        """The next ``count`` requests are answered ``seconds`` late."""
        with self._lock:
            self._queue.append(_Fault("delay", count, seconds=seconds))

    def drop(self) -> None:
        """The next request closes its connection (no answer)."""
        with self._lock:
            self._queue.append(_Fault("drop", 1))

    def clear(self) -> None:
        """Forget armed faults."""
        with self._lock:
            self._queue.clear()

    def take(self) -> _Fault | None:
        """The fault for the request being served, if any."""
        if not self._queue:
            return None
        with self._lock:
            fault = self._queue[0]
            fault.count -= 1
            if fault.count <= 0:
                self._queue.pop(0)
            self.injected += 1
            return fault


class _Context(ModbusServerContext):
    """pymodbus datastore adapter: one unit id, holding registers, fault injection."""

    def __init__(self, sim: "ModbusSimServer") -> None:  # pylint: disable=super-init-not-called
        self._sim = sim
        self.old_simulator = True  # pymodbus then calls our async_getValues/async_setValues directly
        self.simdevices = []
        self._in_fc23 = False

    def device_ids(self) -> list[int]:
        return [self._sim.unit_id]

    async def _fault(self, func_code: int) -> int | None:
        fault = self._sim.faults.take()
        if fault is None:
            return None
        if fault.kind == "exception":
            logger.info("%s: injected exception 0x%02X on function %d", self._sim.drive.name, fault.code, func_code)
            return fault.code
        if fault.kind == "delay":
            await asyncio.sleep(fault.seconds)
            return None
        logger.info("%s: injected connection drop on function %d", self._sim.drive.name, func_code)
        handler = self._sim.current_handler
        if handler is not None and handler.transport is not None:
            handler.transport.abort()
        return ExcCodes.DEVICE_FAILURE  # never sent: the connection is gone

    def _check(self, device_id: int, func_code: int) -> int | None:
        if device_id != self._sim.unit_id:
            raise NoSuchIdException(f"unit id {device_id} (this drive is unit {self._sim.unit_id})")
        if func_code not in _HOLDING:
            return ExcCodes.ILLEGAL_FUNCTION
        return None

    async def async_getValues(self, device_id: int, func_code: int, address: int, count: int = 1) -> list[int] | ExcCodes:
        refused = self._check(device_id, func_code)
        if refused:
            return ExcCodes(refused)
        if self._in_fc23 and func_code == 23:
            self._in_fc23 = False  # second half of one FC23: the fault (if any) was taken already
        else:
            code = await self._fault(func_code)
            if code:
                return ExcCodes(code)
        with self._sim.lock:
            result = self._sim.bank.read(address, count)
        return ExcCodes(result) if isinstance(result, int) else result

    async def async_setValues(self, device_id: int, func_code: int, address: int, values: Sequence[int]) -> ExcCodes | None:
        refused = self._check(device_id, func_code)
        if refused:
            return ExcCodes(refused)
        self._in_fc23 = False
        code = await self._fault(func_code)
        if code:
            return ExcCodes(code)
        sim = self._sim
        with sim.lock:
            rc = sim.bank.write(address, values)
        if rc:
            return ExcCodes(rc)
        if address <= CONTROLWORD_REGISTER < address + len(values) or address <= TORQUE_REGISTER < address + len(values):
            sim.controller = sim.current_handler
        self._in_fc23 = func_code == 23
        return None


class _Handler(ServerRequestHandler):
    """A client connection; tells the simulator which connection a request came on, and when it closes."""

    sim: "ModbusSimServer"

    async def handle_request(self) -> None:
        self.sim.current_handler = self
        await super().handle_request()

    def callback_disconnected(self, exc: Exception | None) -> None:
        super().callback_disconnected(exc)
        self.sim._connection_closed(self)


class _TcpServer(ModbusTcpServer):
    sim: "ModbusSimServer"

    def callback_new_connection(self) -> _Handler:
        handler = _Handler(self, self.trace_packet, self.trace_pdu, self.trace_connect)
        handler.sim = self.sim
        return handler


def parse_modbus_url(url: str) -> tuple[str, int]:
    """``tcp://HOST:PORT`` -> (host, port); ParameterError otherwise (port 0 = any free port)."""
    parsed = urllib.parse.urlsplit(url)
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
    event loop (:meth:`serve`).  ``drive`` is the :class:`SimulatedDrive`; change it (operator,
    timing) only between cycles.  ``faults`` arms injected faults.
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
    ) -> None:
        if not 0 <= unit_id <= 255:
            raise ParameterError("unit_id", unit_id, "0..255")
        self.host = host
        self.requested_port = port
        self.unit_id = unit_id
        self.drive = SimulatedDrive(parameters, timing, operator, name=f"Modbus unit {unit_id}")
        self.bank = RegisterBank(self.drive, word_order)
        self.faults = FaultInjector()
        self.lock = threading.Lock()
        self.port: int | None = None
        self.current_handler: _Handler | None = None
        self.controller: _Handler | None = None
        self.connections_closed = 0
        self._server: _TcpServer | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._stopped: asyncio.Event | None = None
        self._error: BaseException | None = None
        self.drive.sync()  # SYNC 0: the first sample at t = 0

    @property
    def url(self) -> str:
        """``tcp://host:port`` of the bound server."""
        return f"tcp://{self.host}:{self.port}"

    def _connection_closed(self, handler: _Handler) -> None:
        self.connections_closed += 1
        if handler is self.current_handler:
            self.current_handler = None
        if handler is not self.controller:
            return
        self.controller = None
        with self.lock:
            if self.drive.state is State.OPERATION_ENABLED:
                logger.warning("%s: the commanding connection closed in OPERATION ENABLED: fault 0x%04X, torque off",
                               self.drive.name, LINK_LOST_ERROR_CODE)
                self.drive.fault(LINK_LOST_ERROR_CODE)

    async def serve(self, stop: asyncio.Event | None = None) -> None:
        """Serve in the running event loop until ``stop`` is set (or the task is cancelled)."""
        self._loop = asyncio.get_running_loop()
        self._stopped = stop or asyncio.Event()
        server = _TcpServer(_Context(self), address=(self.host, self.requested_port))
        server.sim = self
        await server.serve_forever(background=True)
        self._server = server
        sockets = getattr(server.transport, "sockets", None) or []
        self.port = sockets[0].getsockname()[1] if sockets else self.requested_port
        self._ready.set()
        try:
            await self._stopped.wait()
        finally:
            await server.shutdown()
            self._server = None

    # ------------------------------------------------------------------ thread mode
    def start(self, timeout: float = 5.0) -> "ModbusSimServer":
        """Serve in a daemon thread; return once bound (``port`` is then the real port)."""
        if self._thread is not None:
            return self
        self._ready.clear()
        self._thread = threading.Thread(target=self._thread_main, name=f"modbus-sim-{self.unit_id}", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise RuntimeError(f"Modbus simulator did not bind {self.host}:{self.requested_port} within {timeout} s: {self._error}")
        if self._error is not None:
            raise RuntimeError(f"Modbus simulator failed to start: {self._error}") from self._error
        return self

    def _thread_main(self) -> None:
        try:
            asyncio.run(self.serve())
        except BaseException as exc:  # reported by start()
            self._error = exc
            self._ready.set()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the thread started by :meth:`start` (idempotent)."""
        thread, loop, stopped = self._thread, self._loop, self._stopped
        if thread is None:
            return
        if loop is not None and stopped is not None and not loop.is_closed():
            loop.call_soon_threadsafe(stopped.set)
        thread.join(timeout)
        self._thread = None

    def drop_connections(self) -> int:
        """Close every client connection now (from any thread); the number closed."""
        server, loop = self._server, self._loop
        if server is None or loop is None:
            return 0
        handlers = list(server.active_connections.values())

        def close_all() -> None:
            for handler in handlers:
                if handler.transport is not None:
                    handler.transport.abort()

        loop.call_soon_threadsafe(close_all)
        return len(handlers)

    def __enter__(self) -> "ModbusSimServer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


# ---------------------------------------------------------------------- command line
def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``haptic-bus sim --modbus``."""
    parser = argparse.ArgumentParser(prog="haptic-bus sim --modbus", description="Simulated CiA-402 drive as a Modbus TCP server.")
    parser.add_argument("--modbus", required=True, metavar="tcp://HOST:PORT", help="address to serve on (PORT 0: any free port)")
    parser.add_argument("--unit-id", type=int, default=1, help="Modbus unit id (default 1)")
    parser.add_argument("--word-order", choices=["big", "little"], default="big", help="32-bit word order (big: high word first)")
    parser.add_argument("--timing", choices=[t.value for t in Timing],
                        help="cia402 (default) or ideal; default: the profile's [loop] timing")
    parser.add_argument("--profile", help="operator profile (name or TOML path): [device], [loop], [operator_model]")
    parser.add_argument("--realtime", action="store_true", help="timestamp log lines with the wall clock")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``haptic-bus sim --modbus ...`` until SIGINT/SIGTERM; return the exit status."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2): report, do not exit
        return int(exc.code or 0)
    fmt = "%(asctime)s %(message)s" if args.realtime else "%(message)s"
    logging.basicConfig(level=logging.INFO, format=fmt, stream=sys.stderr, force=True)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    try:
        from sim_drive.profile import load_profile

        host, port = parse_modbus_url(args.modbus)
        profile = load_profile(args.profile) if args.profile else None
        parameters = profile.parameters if profile else DeviceParameters()
        operator = profile.operator if profile else None
        args.timing = args.timing or (profile.timing.value if profile and profile.timing else Timing.CIA402.value)
        sim = ModbusSimServer(host, port, unit_id=args.unit_id, timing=args.timing, parameters=parameters,
                              operator=operator, word_order=args.word_order)
    except ParameterError as exc:
        print(f"haptic-bus sim: error: {exc}", file=sys.stderr)
        return 2

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        task = asyncio.create_task(sim.serve(stop))
        while not sim._ready.is_set() and not task.done():
            await asyncio.sleep(0.005)
        if task.done():
            await task  # raises the bind error
        logger.info("unit %d: serving Modbus TCP on %s (timing %s, word order %s, started %.3f)",
                    sim.unit_id, sim.url, args.timing, args.word_order, time.time())
        await task

    try:
        asyncio.run(run())
    except (OSError, RuntimeError) as exc:
        print(f"haptic-bus sim: error: cannot serve on {args.modbus}: {exc}", file=sys.stderr)
        return 1
    drive = sim.drive
    logger.info("unit %d: stopped after %d cycles, virtual time %.6f s, operator energy %.6g J, wall energy %.6g J",
                sim.unit_id, sim.bank.cycles, drive.time, drive.operator_energy, drive.wall_energy)
    return 0


if __name__ == "__main__":
    sys.exit(main())
