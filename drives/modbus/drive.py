"""CiA-402 master over Modbus (TCP, or RTU on a serial port): one servo drive in CST mode.

Built on pymodbus' synchronous clients; the register map is :mod:`drives.modbus.register_map`.  One
cycle is one read of the input block (statusword, velocity[, position]) plus one write of the
output block (controlword, target torque).  Two ways to put that on the wire (``cycle=``):

``"split"`` (default)
    ``read_inputs`` = FC03 read of the input block, ``write_outputs`` = FC16 write of the
    output block: two requests per cycle; the torque leaves as soon as it is computed, so in
    real time the sample-to-torque latency is one read plus one write round trip.
``"fc23"``
    ``write_outputs`` = one FC23 read/write request: it writes this cycle's outputs and (Modbus
    order: write first) reads the inputs of the next cycle, which the next ``read_inputs``
    returns without a request (the very first ``read_inputs``, and the first after any
    acyclic access, is an FC03).  One request per cycle.  In virtual time (the simulated
    drive only advances on the output write) this is exactly equivalent to ``"split"``; in real
    time a loop paced at ``T`` uses inputs sampled up to one period earlier, one more sample of
    loop delay (see :mod:`drives.modbus.timing`).

The hot path reuses its pymodbus request objects (the output registers are updated in place)
and precompiled ``struct`` codecs.  Requests and their typed errors are :mod:`drives.modbus.link`'s:
no silent retry or reconnect.  A timeout, a dropped connection, a Modbus exception response
or a fault bit makes the master attempt one zero-torque write (controlword DISABLE VOLTAGE)
where the link still answers, close the link where it cannot be trusted (timeouts, drops:
:class:`~drives.errors.ModbusLinkLost`), and raise.  After that, ``write_outputs`` writes the
safe output block instead of the caller's torque (while the link is up), until
:meth:`ModbusDrive.fault_reset` or :meth:`ModbusDrive.enable`; a closed link needs an
explicit :meth:`ModbusDrive.reconnect`.

As on CANopen (:mod:`drives.canopen.drive`), ``connect()`` returns what the connection found
(:class:`ModbusConnection`: which simulated timing the server states), kept by the drive until
``close()``, and a loop takes its cycles from ``with drive.cyclic(limit) as cycle``
(:class:`~drives.base.DriveCycle`: ``read``/``saturate``/``write`` bound once, the requests
built at construction).  The link itself exists from construction: pymodbus' client is opened
by ``connect()`` and may be dropped and reopened (:meth:`ModbusDrive.reconnect`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

from pymodbus.pdu import ModbusPDU

from drives.base import CyclicInputs, DriveCycle, DriveScaling
from drives.cia402 import (
    ABORT_CONNECTION_OPTION_CODE,
    CONTROLWORD,
    ERROR_CODE,
    MAX_TORQUE,
    MOTOR_RATED_TORQUE,
    SAFE_CONTROLWORD,
    STATUSWORD,
    TARGET_TORQUE,
    ObjectSpec,
    State,
    decode_statusword,
)
from drives.cia402_master import Cia402Master
from drives.errors import DriveError, DriveProtocolError, DriveRefusal, DriveTimeout, ModbusLinkLost, ParameterError
from drives.modbus.cyclic_requests import CyclicRequests
from drives.modbus.link import ModbusAddress, ModbusLink, ModbusStats
from drives.modbus.register_map import (
    MAP_IDENTITY,
    REGISTER_BY_NAME,
    SIM_TIMING_CODES,
    UNIT_ID_RANGE,
    UNIT_IDS,
    InputBlockCodec,
    RegisterSpec,
    decode_value,
    encode_value,
    register_for_object,
)
from drives.safety import DEFAULT_SAFETY, SafetySettings

logger = logging.getLogger(__name__)

__all__ = ["CYCLE_MODES", "ModbusConnection", "ModbusDrive", "ModbusStats"]

CYCLE_MODES = ("split", "fc23")
_TIMING_NAMES = {code: name for name, code in SIM_TIMING_CODES.items()}
_TIMING_DELAYS = {"ideal": 0, "cia402": 1}  # samples; "reception" reads its delay from 0x0060
_CONTROLWORD_REG = register_for_object(CONTROLWORD)
_TORQUE_REG = register_for_object(TARGET_TORQUE)
_STATUSWORD_REG = register_for_object(STATUSWORD)


@dataclass(frozen=True, slots=True)
class ModbusConnection:
    """What ``connect()`` found besides the scaling: ``simulated_timing`` ("ideal", "cia402",
    "reception") when the server is the simulated drive (None otherwise) and ``simulated_delay``,
    that drive's loop delay in samples (None otherwise)."""

    simulated_timing: str | None = None
    simulated_delay: float | None = None


class ModbusDrive(Cia402Master[ModbusConnection]):
    """A CiA-402 drive reached over Modbus TCP (``host``, ``port``) or RTU (``port`` = serial path).

    ``unit_id``: the Modbus unit (device id) 1..247 (:data:`~drives.modbus.register_map.UNIT_ID_RANGE`: 0
    is broadcast, which no unit answers); ``timeout`` (s): answer timeout of every
    request (also the TCP connect timeout); ``word_order``: of 32/64-bit values ("big" = high
    word first); ``cycle``: "split" or "fc23" (module docstring); ``with_position``: read
    0x6064 each cycle (the default: the controller's port observer needs it); ``scaling``: the
    caller's :class:`DriveScaling`, whose fields are replaced by 0x6076/0x6072 and the
    manufacturer scaling registers where the drive has them (``scaling_source`` names it in the
    report and in a disagreement, e.g. "profile [device]");
    ``state_timeout`` (s): per state-machine step; ``check_identity``: verify the map identity
    register (catches a word-order mismatch).  RTU: ``baudrate``, ``parity``, ``stopbits``,
    ``bytesize`` (needs pyserial at connect time).
    """

    stats: ModbusStats

    def __init__(
        self,
        host: str | None = "127.0.0.1",
        port: int | str = 502,
        *,
        unit_id: int = 1,
        timeout: float = 0.1,
        word_order: str = "big",
        cycle: str = "split",
        with_position: bool = True,
        scaling: DriveScaling | None = None,
        scaling_source: str = "caller",
        state_timeout: float = 1.0,
        check_identity: bool = True,
        baudrate: int = 115200,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
        safety: SafetySettings = DEFAULT_SAFETY,
    ) -> None:
        if isinstance(host, str) and ("://" in host or host.startswith("rtu:")):
            raise ParameterError("host", host, "a host name or address (a URL: ModbusDrive.from_url)", "Modbus drive")
        self._setup(ModbusAddress(host, port, timeout, baudrate, parity, stopbits, bytesize), unit_id, word_order,
                    cycle, with_position, (scaling, scaling_source), state_timeout, check_identity, safety)

    def _setup(self, address: ModbusAddress, unit_id: int, word_order: str, cycle: str, with_position: bool,
               scaling: tuple[DriveScaling | None, str], state_timeout: float, check_identity: bool,
               safety: SafetySettings) -> None:
        low, high = UNIT_ID_RANGE
        if isinstance(unit_id, bool) or not isinstance(unit_id, int) or not low <= unit_id <= high:
            raise ParameterError("unit_id", unit_id, UNIT_IDS, "Modbus drive")
        if cycle not in CYCLE_MODES:
            raise ParameterError("cycle", cycle, " or ".join(map(repr, CYCLE_MODES)), "Modbus drive")
        stats = ModbusStats()
        self._init_master(f"Modbus unit {unit_id} at {address.url}", stats, *scaling)
        self.unit_id = unit_id
        self.cycle = cycle
        self.state_timeout = state_timeout
        self.max_commands_per_step = 10_000
        self.check_identity = check_identity
        self.safety = safety
        self.safety_warnings: tuple[str, ...] = ()
        self.link = ModbusLink(self.name, address, stats)
        self._codec = InputBlockCodec(word_order, with_position)
        self._requests = CyclicRequests(unit_id, self._codec.count)

    @classmethod
    def from_url(cls, url: str, *, timeout: float = 0.1, **options: Any) -> ModbusDrive:
        """``tcp://HOST:PORT`` or ``rtu:/dev/ttyUSB0`` -> a ModbusDrive (``options`` as the constructor)."""
        address = ModbusAddress.from_url(url, timeout)
        return cls(address.host, address.port, timeout=timeout, **options)

    @property
    def address(self) -> str:
        """``tcp://HOST:PORT`` or ``rtu:/dev/...``."""
        return self.link.address.url

    @property
    def word_order(self) -> str:
        """Order of the 16-bit words of 32/64-bit values: "big" (high word first) or "little"."""
        return self._codec.word_order

    @property
    def with_position(self) -> bool:
        """True when each cycle reads 0x6064 too."""
        return self._codec.with_position

    @property
    def simulated_delay(self) -> float | None:
        """That simulated drive's loop delay, samples (after connect())."""
        return self.connection.simulated_delay if self.connection is not None else None

    @property
    def link_up(self) -> bool:
        """True while the link is open and trusted."""
        return self.link.up

    # ------------------------------------------------------------------ link

    def _drop_link(self) -> None:
        self._requests.cached = None
        self.link.drop()

    def _establish(self) -> ModbusConnection:
        """Open the link, check the map identity, read scaling (0x6076, 0x6072, 0x0040..) (connect() calls it);
        raise DriveTimeout."""
        self.link.open()
        self._requests.cached = None
        try:
            return self._configure()
        except BaseException:
            self._drop_link()
            raise

    def reconnect(self) -> ModbusConnection:
        """Close and reopen the link (explicit; never done silently), re-check identity and scaling.

        The trip state stays: call :meth:`fault_reset` or :meth:`enable` afterwards.
        """
        self._drop_link()
        self.connection = None
        self._armed = False
        return self.connect()  # DriveError if the drive object is closed

    def _configure(self) -> ModbusConnection:
        if self.check_identity:
            self.check_map_identity()
        self._adopt_scaling(self.stated_scaling())
        try:
            timing = _TIMING_NAMES.get(int(self._read_spec(REGISTER_BY_NAME["sim_timing"])))
        except DriveProtocolError:
            return ModbusConnection()
        if timing == "reception":
            return ModbusConnection(timing, float(self._read_spec(REGISTER_BY_NAME["sim_reception_delay"])))
        return ModbusConnection(timing, None if timing is None else float(_TIMING_DELAYS[timing]))

    def check_map_identity(self) -> None:
        """DriveProtocolError unless the map identity register 0x0030 reads the haptic_bus map in this
        word order (the link must be open: :meth:`connect`, or ``link.open()`` for reads alone)."""
        identity = int(self._read_spec(REGISTER_BY_NAME["map_identity"]))  # a UINT32 register
        if identity != MAP_IDENTITY:
            swapped = (identity & 0xFFFF) << 16 | identity >> 16
            hint = (f"; the server uses the other word order than word_order={self.word_order!r}"
                    if swapped == MAP_IDENTITY else "; not the haptic_bus register map")
            raise DriveProtocolError(
                self.name, f"map identity register 0x0030 reads 0x{identity:08X}, expected 0x{MAP_IDENTITY:08X}{hint}")

    def stated_scaling(self) -> dict[str, tuple[float | int, str]]:
        """What the drive's registers state (0x6076, 0x6072, the scaling registers 0x0040..): field ->
        (value, register); a register the drive refuses is left out (the link must be open)."""
        sources: list[tuple[str, RegisterSpec, float]] = [
            ("rated_torque", register_for_object(MOTOR_RATED_TORQUE), 1e-3),  # mN m -> N m
            ("max_torque_permille", register_for_object(MAX_TORQUE), 1),
            ("velocity_per_count", REGISTER_BY_NAME["velocity_per_count"], 1.0),
            ("position_per_count", REGISTER_BY_NAME["position_per_count"], 1.0),
            ("force_per_torque", REGISTER_BY_NAME["force_per_torque"], 1.0),
        ]
        found: dict[str, tuple[float | int, str]] = {}
        for field_name, spec, factor in sources:
            try:
                raw = self._read_spec(spec)
            except DriveProtocolError as exc:
                logger.info("%s: the drive states no %s (%s)", self.name, field_name, exc)
                continue
            found[field_name] = (raw if factor == 1 and isinstance(raw, int) else raw * factor,
                                 f"register 0x{spec.address:04X}")
        return found

    # ------------------------------------------------------------------ requests

    def read_registers(self, address: int, count: int) -> list[int]:
        """Raw FC03 read of ``count`` holding registers from ``address`` (acyclic)."""
        self._require_link()
        self._requests.cached = None
        return self.link.read_holding(self.unit_id, address, count)

    def write_registers(self, address: int, values: list[int]) -> None:
        """Raw write of holding registers from ``address`` (FC06 for one, FC16 for more; acyclic)."""
        self._require_link()
        self._requests.cached = None
        self.link.write_holding(self.unit_id, address, values)

    def _read_spec(self, spec: RegisterSpec) -> int | float:
        return decode_value(spec, self.read_registers(spec.address, spec.count), self.word_order)

    def read_object(self, spec: ObjectSpec | int) -> int:
        """Read a CiA-402 object of the register map, in drive units."""
        return int(self._read_spec(register_for_object(spec)))

    def write_object(self, spec: ObjectSpec | int, value: int) -> None:
        """Write a CiA-402 object of the register map, in drive units (ParameterError if out of range)."""
        reg = register_for_object(spec)
        if reg.access != "rw":
            raise ParameterError("register", reg.label, "a writable register (this one is read-only)", self.name)
        self.write_registers(reg.address, encode_value(reg, value, self.word_order))

    def _require_link(self) -> None:
        if self.link.client is None:
            self.connected()  # before connect() or after close(): says which
            raise ModbusLinkLost(self.name, "the Modbus link is down; reconnect() first")

    # ------------------------------------------------------------------ safety

    def _send_safe_outputs(self) -> None:
        """One attempt to write zero torque with DISABLE VOLTAGE, if the link is up; never raises.  It
        runs on a trip, beside the error being raised (the command's one line): a failure here, on
        a link that error took down too (every axis of a server that died), is logged at INFO (``-v``)."""
        self._requests.cached = None
        if not self.link.up:
            return
        requests = self._requests
        requests.outputs[0] = SAFE_CONTROLWORD
        requests.outputs[1] = 0
        try:
            self.link.send(requests.write, f"writing the safe outputs to {requests.write_what}")
        except DriveError as exc:
            logger.info("%s: could not write zero torque: %s", self.name, exc.message)

    def _cyclic(self, request: ModbusPDU, what: str) -> ModbusPDU:
        """A cyclic request; any failure trips (a timeout also closes the link: a late answer
        could not be told from the next one)."""
        try:
            return self.link.send(request, what)
        except ModbusLinkLost as exc:
            raise self.trip(exc) from exc.__cause__
        except DriveTimeout as exc:
            self._send_safe_outputs()
            self._drop_link()
            lost = ModbusLinkLost(self.name, f"{exc.message}; link closed (a late answer could not be told from "
                                             f"the next) until the master reconnects")
            raise self.trip(lost) from exc.__cause__
        except DriveProtocolError as exc:
            raise self.trip(exc) from exc.__cause__

    def _fault_detail(self) -> tuple[str, int | None]:
        try:
            code = self.read_object(ERROR_CODE)
        except DriveError:
            return "", None
        return f", error code 0x{code:04X}", code

    # ------------------------------------------------------------------ cyclic hot path

    def read_inputs(self) -> CyclicInputs:
        """This cycle's statusword, velocity[, position]: FC03, or the inputs the last FC23 brought."""
        self.connected()
        return self._cycle_inputs()

    def _bind_cycle(self) -> DriveCycle:
        """The cycle's read past the connection check (done once here)."""
        self.connected()
        return DriveCycle(self.name, self._cycle_inputs, self.clamp, self._send_torque)

    def _cycle_inputs(self) -> CyclicInputs:
        requests = self._requests
        registers = requests.cached
        if registers is None:
            self.stats.cyclic_requests += 1
            registers = self._cyclic(requests.read, requests.read_label).registers
            answered = time.perf_counter_ns()  # the drive sampled before it answered
        else:
            requests.cached = None
            answered = requests.cached_at
        if len(registers) != self._codec.count:
            raise self.trip(DriveProtocolError(
                self.name, f"{len(registers)} registers answered for {requests.read_what}, expected {self._codec.count}"))
        statusword, velocity, position = self._codec.decode(registers)
        return self.accept_inputs(CyclicInputs(statusword, velocity, position, sampled_by_ns=answered))

    def _send_outputs(self, controlword: int, target_torque: int) -> None:
        if not self.link.up:
            raise ModbusLinkLost(self.name, f"link is down after: {self._tripped}; down until the master reconnects")
        requests = self._requests
        requests.outputs[0] = controlword
        requests.outputs[1] = target_torque & 0xFFFF
        self.stats.cyclic_requests += 1
        if self.cycle == "fc23":
            requests.cached = self._cyclic(requests.read_write, requests.read_write_label).registers
            requests.cached_at = time.perf_counter_ns()
        else:
            self._cyclic(requests.write, requests.write_label)

    # ------------------------------------------------------------------ state machine

    def statusword(self) -> int:
        """0x6041 read acyclically."""
        return int(self._read_spec(_STATUSWORD_REG))

    def state(self) -> State | None:
        """The drive's current CiA-402 state (one acyclic read)."""
        return decode_statusword(self.statusword())

    def _command(self, controlword: int) -> int:
        self.write_registers(_CONTROLWORD_REG.address, [controlword])
        return self.statusword()

    def _before_enable(self) -> None:
        self.write_object(TARGET_TORQUE, 0)  # no stale torque at the enable edge
        self._set_up_safety()

    def _set_up_safety(self) -> None:
        """The drive's 0x6007 and communication watchdog (register 0x002A), each read back; a drive
        without them gets a warning naming what is missing, or a refusal when ``safety.strict``."""
        safety = self.safety
        missing = []
        for spec, value, what in ((register_for_object(ABORT_CONNECTION_OPTION_CODE), safety.abort_option,
                                   "0x6007 abort connection option code (register 0x002B)"),
                                  (REGISTER_BY_NAME["comm_watchdog_ms"], safety.modbus_watchdog_ms,
                                   "the communication watchdog (register 0x002A)")):
            try:
                self.write_registers(spec.address, encode_value(spec, value, self.word_order))
                got = self._read_spec(spec)
            except DriveRefusal as exc:
                if exc.code != 0x02:  # anything but "no such register"
                    raise
                missing.append(what)
                continue
            if got != value:
                raise DriveProtocolError(self.name, f"{what} reads back {got} after writing {value}")
        if not missing:
            self.safety_warnings = ()
            return
        text = (f"the drive lacks {', '.join(missing)}: it will not stop on its own if this master dies; "
                "a drive watchdog (or an emergency stop) must cover it")
        if safety.strict:
            raise DriveProtocolError(self.name, f"refused under the strict safety policy: {text}")
        logger.warning("%s: %s", self.name, text)
        self.safety_warnings = (text,)

    def disable(self) -> None:
        """Zero torque, DISABLE VOLTAGE, and check the drive reaches SWITCH ON DISABLED (or sits in FAULT)."""
        if self.connection is None:
            return
        super().disable()

    def mark_disabled(self) -> None:
        """DISABLE VOLTAGE held from now on (the fault bit no longer trips), and the target torque
        register zeroed at once: before the walk to SWITCH ON DISABLED, alone or walked with other axes."""
        super().mark_disabled()
        self.write_object(TARGET_TORQUE, 0)

    # ------------------------------------------------------------------ shutdown

    def close(self) -> None:
        """Write the safe outputs if the link is up (one attempt), then close the link."""
        if self._closed:
            return
        self._closed = True
        if self.connection is not None and self.link.up:
            self._armed = False
            try:
                self.write_registers(_TORQUE_REG.address, [0])
                self._command(SAFE_CONTROLWORD)
            except DriveError as exc:
                logger.warning("%s: could not write the safe outputs on close: %s", self.name, exc)
        self._drop_link()
        self.connection = None
        self.link.client = None

    def __repr__(self) -> str:
        return f"ModbusDrive({self.address!r}, unit_id={self.unit_id}, cycle={self.cycle!r}, word_order={self.word_order!r})"
