"""Holding-register reads and writes against a :class:`~sim_drive.device.SimulatedDrive` (no network).

The register map is :mod:`drives.modbus.register_map`; values are encoded and decoded with its
``encode_value``/``decode_value``, so the server and the master share one codec.

Virtual time.  Modbus has no SYNC; the controller's write of the output block stands for it.
A write that covers the whole output block 0x0010..0x0011 (FC16 of the block, or the write
half of an FC23) applies its registers in address order (controlword, then target torque) and
then runs one :meth:`SimulatedDrive.sync`: the plant advances by exactly ``T`` and the inputs
are sampled.  So the write of cycle k is SYNC k+1 of the CANopen simulator with the RPDO of
cycle k applied just before it: with ``ideal`` timing the torque written in answer to sample k
acts during [t_k, t_k+1); with ``cia402`` it is latched at that SYNC and acts one period later.
Reads never advance time; a write of the controlword or the target torque alone (FC06) acts at
once without advancing the plant (acyclic commissioning: the state machine walk).

Exceptions: 0x02 for unmapped or read-only registers and for partial access to a multi-register
value, 0x03 for a value outside the object's range (nothing of the request is applied).

Communication watchdog (register 0x002A, ms, 0 = off): :meth:`RegisterBank.watchdog_expired`
is true once no valid request has come for that long while the power stage is on; the
server then applies the drive's 0x6007 reaction (:meth:`SimulatedDrive.connection_lost`,
error code 0x8130).  Every answered request re-arms it.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence

from pymodbus.constants import ExcCodes

from drives.cia402 import ABORT_CONNECTION_OPTION_CODE, QUICK_STOP_OPTION_CODE, AbortConnectionOption
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
    decode_value,
    encode_value,
    register_at,
)
from sim_drive.device import POWER_STAGE_ON, ObjectAccessError, SimulatedDrive
from sim_drive.sync_clock import SyncClock

logger = logging.getLogger("sim_drive.modbus")

__all__ = ["RegisterBank", "writes_command"]

_COMMAND_REGISTERS = (REGISTER_BY_NAME["controlword"].address, REGISTER_BY_NAME["target_torque"].address)
_QUICK_STOP_OPTIONS = range(9)  # the 0x605A values this drive implements: 0..8
# the values the drive refuses of a register that can follow others in one write (0x002B after 0x0029,
# 0x002A): refused before any register is applied
_REFUSED_UNLESS_IN = {QUICK_STOP_OPTION_CODE.index: frozenset(_QUICK_STOP_OPTIONS),
                      ABORT_CONNECTION_OPTION_CODE.index: frozenset(int(option) for option in AbortConnectionOption)}
_WATCHDOG = REGISTER_BY_NAME["comm_watchdog_ms"]
_LAYOUTS_KEPT = 256  # (address, count) of writes whose registers are kept


def writes_command(address: int, count: int) -> bool:
    """True if registers ``address .. address+count-1`` include the controlword or the target torque."""
    return any(address <= register < address + count for register in _COMMAND_REGISTERS)


class RegisterBank:
    """Register reads and writes against a :class:`SimulatedDrive` (no network here).

    ``read(address, count)`` returns the registers or an exception code (int);
    ``write(address, values)`` returns 0 or an exception code.  ``word_order`` is ``"big"``
    (high word first) or ``"little"``.  See the module docstring for when a write closes a cycle;
    ``sync_clock`` (:mod:`sim_drive.sync_clock`) how long the interval it closes was.
    """

    def __init__(self, drive: SimulatedDrive, word_order: str = "big", sync_clock: SyncClock | None = None) -> None:
        self.drive = drive
        self.sync_clock = sync_clock  # how long the interval a cycle-closing write ends was (None: T)
        self.word_order = word_order
        self.cycles = 0  # writes that closed a cycle
        self.watchdog_ms = 0
        self._last_request = time.monotonic()
        self._watchdog_fired = False
        self._inputs = InputBlockCodec(word_order, with_position=True)
        self._sources: dict[RegisterSpec, Callable[[], int | float]] = {
            spec: drive.reader(spec.obj.index) for spec in REGISTERS if spec.obj is not None
        }
        extras: dict[str, Callable[[], int | float]] = {
            "map_identity": lambda: MAP_IDENTITY,
            "velocity_per_count": lambda: drive.parameters.velocity_per_count,
            "position_per_count": lambda: drive.parameters.position_per_count,
            "force_per_torque": lambda: drive.parameters.force_per_torque,
            "sim_timing": lambda: SIM_TIMING_CODES[drive.timing.value],
            "sim_cycle_count": lambda: drive.sync_count & 0xFFFFFFFF,
            "sim_time": lambda: drive.time,
            "sim_operator_energy": lambda: drive.operator_energy,
            "sim_wall_energy": lambda: drive.wall_energy,
            "sim_reception_delay": lambda: drive.parameters.reception_delay,
            "comm_watchdog_ms": lambda: self.watchdog_ms,
        }
        self._sources.update({REGISTER_BY_NAME[name]: source for name, source in extras.items()})
        writable = drive.writable_objects()
        self._writable: dict[RegisterSpec, int] = {  # register -> the index of its object (0: the bank's own)
            spec: spec.obj.index for spec in REGISTERS
            if spec.obj is not None and spec.access == "rw" and spec.obj.index in writable
        }
        self._writable[_WATCHDOG] = 0
        self._layouts: dict[tuple[int, int], tuple[tuple[tuple[RegisterSpec, int, int], ...], int]] = {}

    def _layout(self, address: int, count: int) -> tuple[tuple[tuple[RegisterSpec, int, int], ...], int]:
        """The writable registers a write of ``count`` from ``address`` covers, in order, each with its
        words' slice of the write, up to the first that is not one (then 0x02, else 0); kept per
        (address, count), since the map does not change (the writes of a cycle are the same each time)."""
        key = (address, count)
        layout = self._layouts.get(key)
        if layout is None:
            registers: list[tuple[RegisterSpec, int, int]] = []
            refused, end, a = 0, address + count, address
            while a < end:
                spec = register_at(a)
                if spec is None or spec.address != a or spec.end > end or spec not in self._writable:
                    refused = ExcCodes.ILLEGAL_ADDRESS
                    break
                registers.append((spec, a - address, spec.end - address))
                a = spec.end
            if len(self._layouts) >= _LAYOUTS_KEPT:
                self._layouts.clear()
            layout = self._layouts[key] = (tuple(registers), refused)
        return layout

    def request_served(self, now: float) -> None:
        """A valid request was answered at ``now`` (monotonic s): the watchdog starts over."""
        self._last_request = now
        self._watchdog_fired = False

    def watchdog_deadline(self) -> float:
        """The monotonic time (s) before which :meth:`watchdog_expired` cannot be True (inf while the
        watchdog is off, has fired, or the power stage is off: only a request or a state change arms it)."""
        if not self.watchdog_ms or self._watchdog_fired or self.drive.state not in POWER_STAGE_ON:
            return math.inf
        return self._last_request + self.watchdog_ms / 1000.0

    def watchdog_expired(self, now: float) -> bool:
        """True once (until the next valid request) when the watchdog ran out with the power stage on."""
        if (not self.watchdog_ms or self._watchdog_fired or self.drive.state not in POWER_STAGE_ON
                or now - self._last_request <= self.watchdog_ms / 1000.0):
            return False
        self._watchdog_fired = True
        return True

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

    def write(self, address: int, values: Sequence[int]) -> int:
        """Write ``values`` (each 0..0xFFFF) from ``address``; 0, or 0x02/0x03 with nothing applied."""
        decoded = self._decode(address, values)
        if isinstance(decoded, int):
            return decoded
        drive = self.drive
        for spec, value in decoded:
            if spec is _WATCHDOG:
                self.watchdog_ms = value
                continue
            try:
                drive.write_object(self._writable[spec], value)
            except ObjectAccessError as exc:
                logger.warning("%s: write of %s refused: %s", drive.name, spec.label, exc)
                return ExcCodes.ILLEGAL_VALUE if exc.reason == "range" else ExcCodes.ILLEGAL_ADDRESS
        if address <= OUTPUT_BLOCK and address + len(values) >= OUTPUT_BLOCK + OUTPUT_BLOCK_COUNT:
            if self.sync_clock is None:
                drive.sync()
            else:
                drive.sync(self.sync_clock(time.time()))
            self.cycles += 1
        return 0

    def _decode(self, address: int, values: Sequence[int]) -> list[tuple[RegisterSpec, int]] | int:
        """The (register, value) pairs ``values`` write, or the exception code refusing all of them."""
        registers, refused = self._layout(address, len(values))
        decoded: list[tuple[RegisterSpec, int]] = []
        for spec, start, stop in registers:
            words = list(values[start:stop])
            if any(not 0 <= w <= 0xFFFF for w in words):
                return ExcCodes.ILLEGAL_VALUE
            try:
                value = int(decode_value(spec, words, self.word_order))  # writable registers are integers
            except ValueError:  # an INTEGER8 register that is not sign-extended
                return ExcCodes.ILLEGAL_VALUE
            decoded.append((spec, value))
        if refused:
            return refused
        for spec, value in decoded:  # the drive refuses these too, but only after the registers before them
            allowed = _REFUSED_UNLESS_IN.get(self._writable[spec])
            if allowed is not None and value not in allowed:
                return ExcCodes.ILLEGAL_VALUE
        return decoded
