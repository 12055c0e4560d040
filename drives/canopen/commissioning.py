"""Bringing a CANopen CiA-402 drive up for the cyclic exchange, over SDO and NMT.

In order: make sure no other master drives the bus (no foreign SYNC, the drive not enabled
by someone else), reach the node (NMT reset communication and its boot-up, or an SDO answer),
check 0x1000 is a CiA-402 device, write the cycle period 0x1006, map the TPDOs and RPDO1
through canopen's :meth:`~canopen.pdo.PdoMap.save` (which copes with drives whose mapping
count is fixed), invalidate the PDOs the cycle does not use, read the scaling the drive has,
set up the safety chain (:class:`SafetySettings`: the drive's heartbeat consumer 0x1016 for
the master's heartbeat, the RPDO deadline 0x1400:05, the abort connection option 0x6007,
each read back), set its heartbeat 0x1017, NMT start, and wait until its heartbeat shows
OPERATIONAL.

Scaling: what the drive states, :mod:`drives.canopen.stated_scaling` (the standard objects
0x6076, 0x6072 and the factor group where the drive has them, manufacturer objects only where an
EDS the user gave names them).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import cast

import canopen
from canopen.pdo.base import PdoMap

from drives.base import ScalingReading
from drives.canopen.events import DriveEvents
from drives.canopen.pdo_codec import PdoCodec
from drives.canopen.sdo import SdoAccess
from drives.canopen.stated_scaling import read_stated_scaling
from drives.cia301 import (
    COB_ID_INVALID,
    COB_ID_MASK,
    COB_ID_NO_RTR,
    COMMUNICATION_CYCLE_PERIOD,
    CONSUMER_HEARTBEAT_TIME,
    DEVICE_PROFILE_402,
    DEVICE_TYPE,
    PDO_COB_ID,
    PDO_EVENT_TIMER,
    PRODUCER_HEARTBEAT_TIME,
    RPDO_BASES,
    RPDO_COMMUNICATION,
    SYNC_COB_ID,
    TPDO_BASES,
    TPDO_COMMUNICATION,
    TRANSMISSION_SYNCHRONOUS_EVERY_SYNC,
    NmtCommand,
    NmtState,
    SdoAbort,
)
from drives.cia402 import (
    ABORT_CONNECTION_OPTION_CODE,
    STATUSWORD,
    DataType,
    State,
    decode_statusword,
)
from drives.errors import DriveError, DriveProtocolError, DriveTimeout, SdoAbortError
from drives.safety import SafetySettings

logger = logging.getLogger(__name__)

PDO_CHANNELS = 4


@dataclass(frozen=True)
class CommissioningSettings:
    """How to bring the drive up: ``period`` (s, written to 0x1006), ``boot_timeout`` and
    ``sdo_timeout`` (s), whether to reset communication first and check 0x1000, the drive's
    heartbeat producer time 0x1017 and how long the master tolerates its silence (ms, 0 = off)."""

    period: float
    boot_timeout: float
    sdo_timeout: float
    reset_communication: bool
    check_device_type: bool
    heartbeat_producer_ms: int
    heartbeat_consumer_ms: int


@dataclass(frozen=True)
class Commissioned:
    """What commissioning found: 0x1000, the PDO COB-IDs, the drive's scaling readings per field
    (in order of precedence) with notes on what its objects cannot give, and the safety objects
    the drive lacks (each a warning, unless ``strict`` refused)."""

    device_type: int | None
    tpdo_cobs: tuple[int, ...]
    rpdo_cob: int
    scaling: dict[str, tuple[ScalingReading, ...]]
    scaling_notes: tuple[str, ...] = ()
    safety_warnings: tuple[str, ...] = field(default_factory=tuple)


class Commissioning:
    """One commissioning run against ``node`` (see the module docstring)."""

    def __init__(self, name: str, node: canopen.RemoteNode, sdo: SdoAccess, events: DriveEvents,
                 settings: CommissioningSettings, safety: SafetySettings) -> None:
        self.name = name
        self.node = node
        self.sdo = sdo
        self.events = events
        self.settings = settings
        self.safety = safety

    def run(self, tpdo_codecs: tuple[PdoCodec, ...], rpdo_codec: PdoCodec) -> Commissioned:
        """Commission the drive for ``tpdo_codecs`` (TPDO1..) and ``rpdo_codec`` (RPDO1)."""
        self._reach()
        device_type = self._check_device_type() if self.settings.check_device_type else None
        self.sdo.write_int(COMMUNICATION_CYCLE_PERIOD, 0, DataType.UNSIGNED32, round(self.settings.period * 1e6))
        node_id = cast(int, self.node.id)  # canopen types it Optional; a RemoteNode always has one
        tpdo_cobs = tuple(self._remap(self.node.tpdo[n + 1], codec, TPDO_BASES[n] + node_id)
                          for n, codec in enumerate(tpdo_codecs))
        deadline_ms = self.safety.rpdo_deadline_ms(self.settings.period)
        rpdo_cob = self._remap(self.node.rpdo[1], rpdo_codec, RPDO_BASES[0] + node_id, deadline_ms)
        for n in range(len(tpdo_codecs), PDO_CHANNELS):
            self._invalidate(TPDO_COMMUNICATION + n)
        for n in range(1, PDO_CHANNELS):
            self._invalidate(RPDO_COMMUNICATION + n)
        scaling, notes = self._read_scaling()
        warnings = self._set_up_safety(deadline_ms)
        self._start()
        return Commissioned(device_type, tpdo_cobs, rpdo_cob, scaling, notes, warnings)

    def refuse_another_master(self) -> None:
        """Listen before taking the bus: a SYNC from someone else, or the drive enabled by someone
        else, means another master is at work; refuse rather than reset the drive under it."""
        window = max(0.05, 3 * self.settings.period)
        seen: list[float] = []
        lock = threading.Lock()

        def on_sync(can_id: int, data: bytearray, timestamp: float) -> None:
            with lock:
                seen.append(timestamp)

        network = self.node.network
        network.subscribe(SYNC_COB_ID, on_sync)
        try:
            time.sleep(window)
        finally:
            network.unsubscribe(SYNC_COB_ID, on_sync)
        if seen:
            raise DriveError(
                self.name,
                f"another SYNC producer is on the bus ({len(seen)} SYNC frames in {window * 1e3:.0f} ms): another master "
                "is running; stop it before starting this one",
            )
        self._refuse_an_enabled_drive()

    def _refuse_an_enabled_drive(self) -> None:
        """A drive already in OPERATION ENABLED is driven by someone else (this master always
        leaves it disabled, and the drive's own watchdog stops it when a master dies).  Asked
        before the NMT reset, which would itself abort that connection."""
        sdo = self.node.sdo
        saved = sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES
        sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = self.settings.boot_timeout, 1
        try:
            state = decode_statusword(self.sdo.read_int(STATUSWORD.index, 0, DataType.UNSIGNED16))
        except DriveError:
            return  # no answer (yet): reaching the node says why
        finally:
            sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = saved
        if state is State.OPERATION_ENABLED:
            raise DriveError(
                self.name,
                "the drive is in OPERATION ENABLED before this master enabled it: another master drives it "
                "(without SYNC); stop that master, or disable the drive, before starting this one",
            )

    def _reach(self) -> None:
        """Reset communication and wait for the boot-up message, or for an SDO answer."""
        timeout = self.settings.boot_timeout
        how = "NMT reset communication"
        self.events.forget_state()
        if self.settings.reset_communication:
            self.node.nmt.send_command(NmtCommand.RESET_COMMUNICATION)
            if self.events.wait_for_state(NmtState.BOOT_UP, timeout):
                return
        else:
            how = "NMT pre-operational"
            self.node.nmt.send_command(NmtCommand.ENTER_PRE_OPERATIONAL)
        # No boot-up (a drive may not reset communication on command): does it answer SDO?
        sdo = self.node.sdo
        saved = sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES
        sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = timeout, 1
        try:
            self.sdo.upload(DEVICE_TYPE, 0)
            return
        except SdoAbortError:
            return  # it answered
        except DriveTimeout:
            pass
        finally:
            sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = saved
        seen = sorted(n for n in self.node.network.scanner.nodes if n != self.node.id)
        hint = f"; nodes seen on the bus: {', '.join(map(str, seen))}" if seen else "; no other node seen on the bus"
        raise DriveTimeout(
            self.name,
            f"no boot-up after {how} and no SDO answer within {timeout:.3g} s "
            f"(check node id {self.node.id}, bitrate, wiring{hint})",
        )

    def _check_device_type(self) -> int:
        device_type = self.sdo.read_int(DEVICE_TYPE, 0, DataType.UNSIGNED32)
        if device_type & 0xFFFF != DEVICE_PROFILE_402:
            raise DriveProtocolError(
                self.name,
                f"0x1000 device type = 0x{device_type:08X} is not a CiA-402 drive "
                f"(profile {device_type & 0xFFFF}, expected {DEVICE_PROFILE_402})",
            )
        return device_type

    def _remap(self, pdo: PdoMap, codec: PdoCodec, predefined: int, event_timer_ms: int = 0) -> int:
        """Map ``codec``'s objects into ``pdo``, synchronous (every SYNC), valid, with an event
        timer (an RPDO's receive deadline) if ``event_timer_ms`` and the drive has sub 5; its COB-ID."""
        com = pdo.com_record.od.index
        current = self.sdo.read_int(com, PDO_COB_ID, DataType.UNSIGNED32)
        cob_id = current & COB_ID_MASK or predefined
        if cob_id != predefined:
            logger.info("%s: 0x%04X uses COB-ID 0x%X, not the predefined 0x%X", self.name, com, cob_id, predefined)
        pdo.clear()
        for entry in codec.entries:
            pdo.add_variable(entry.index, entry.subindex)
        if len(pdo.map) != len(codec.entries):
            raise DriveProtocolError(self.name, f"cannot map {codec}: the object dictionary lacks one of its objects")
        pdo.cob_id = cob_id
        pdo.trans_type = TRANSMISSION_SYNCHRONOUS_EVERY_SYNC
        pdo.rtr_allowed = not current & COB_ID_NO_RTR  # keep what the drive had: some refuse RTR
        pdo.enabled = True
        pdo.event_timer = event_timer_ms if event_timer_ms and PDO_EVENT_TIMER in pdo.com_record.od else None
        with self.sdo.translated("mapping", com, PDO_COB_ID):
            pdo.save()
        self.node.network.unsubscribe(cob_id, pdo.on_message)  # the cyclic path decodes its own frames
        mapping = pdo.map_array.od.index
        count = self.sdo.read_int(mapping, 0, DataType.UNSIGNED8)
        if count != len(codec.entries):
            raise DriveProtocolError(
                self.name, f"0x{mapping:04X}:00 reads back {count} mapped objects after writing {len(codec.entries)}"
            )
        return cob_id

    def _invalidate(self, com: int) -> None:
        """Invalidate an unused PDO so that only the configured frames travel (absent PDOs are fine)."""
        try:
            current = self.sdo.read_int(com, PDO_COB_ID, DataType.UNSIGNED32)
            if not current & COB_ID_INVALID:
                self.sdo.write_int(com, PDO_COB_ID, DataType.UNSIGNED32, current | COB_ID_INVALID)
        except SdoAbortError as exc:
            if exc.abort_code not in (SdoAbort.NO_OBJECT, SdoAbort.NO_SUBINDEX):
                raise

    def _read_scaling(self) -> tuple[dict[str, tuple[ScalingReading, ...]], tuple[str, ...]]:
        """The scaling the drive states (:func:`drives.canopen.stated_scaling.read_stated_scaling`)."""
        return read_stated_scaling(self.name, self.sdo, self.node.object_dictionary)

    def _set_up_safety(self, deadline_ms: int) -> tuple[str, ...]:
        """0x1016 sub 1, 0x6007 and (already written with the mapping) 0x1400:05, each read back.

        A drive without one of them gets a warning naming it, or a refusal when ``strict``.
        """
        safety = self.safety
        missing: list[str] = []
        wanted: list[tuple[int, int, DataType, int, str]] = [
            (ABORT_CONNECTION_OPTION_CODE.index, 0, DataType.INTEGER16, safety.abort_option,
             "0x6007 abort connection option code"),
        ]
        if safety.master_node_id is not None:
            entry = safety.master_node_id << 16 | safety.consumer_ms
            wanted.append((CONSUMER_HEARTBEAT_TIME, 1, DataType.UNSIGNED32, entry, "0x1016:01 consumer heartbeat time"))
        for index, subindex, data_type, value, what in wanted:
            try:
                self.sdo.write_int(index, subindex, data_type, value)
                got = self.sdo.read_int(index, subindex, data_type)
            except SdoAbortError as exc:
                if exc.abort_code not in (SdoAbort.NO_OBJECT, SdoAbort.NO_SUBINDEX):
                    raise
                missing.append(what)
                continue
            if got != value:
                raise DriveProtocolError(self.name, f"{what} reads back {got} after writing {value}")
        if deadline_ms:
            try:
                got = self.sdo.read_int(RPDO_COMMUNICATION, PDO_EVENT_TIMER, DataType.UNSIGNED16)
            except SdoAbortError as exc:
                if exc.abort_code not in (SdoAbort.NO_OBJECT, SdoAbort.NO_SUBINDEX):
                    raise
                missing.append("0x1400:05 RPDO1 event timer (receive deadline)")
            else:
                if got != deadline_ms:
                    raise DriveProtocolError(self.name,
                                             f"0x1400:05 RPDO1 event timer reads back {got} ms after writing {deadline_ms}")
        if not missing:
            return ()
        text = (f"the drive lacks {', '.join(missing)}: it will not stop on its own for that cause if this master "
                "dies; a drive watchdog (or an emergency stop) must cover it")
        if safety.strict:
            raise DriveProtocolError(self.name, f"refused under the strict safety policy: {text}")
        logger.warning("%s: %s", self.name, text)
        return (text,)

    def _start(self) -> None:
        """Heartbeat 0x1017, NMT start, and its heartbeat showing OPERATIONAL."""
        producer_ms = self.settings.heartbeat_producer_ms
        self.sdo.write_int(PRODUCER_HEARTBEAT_TIME, 0, DataType.UNSIGNED16, producer_ms)
        self.events.forget_state()
        self.node.nmt.send_command(NmtCommand.START)
        if not producer_ms:
            return
        limit = max(self.settings.boot_timeout, 3 * producer_ms / 1000.0)
        if not self.events.wait_for_state(NmtState.OPERATIONAL, limit):
            raise DriveTimeout(
                self.name,
                f"no heartbeat showing OPERATIONAL within {limit:.3g} s after NMT start (0x1017 = {producer_ms} ms)",
            )
