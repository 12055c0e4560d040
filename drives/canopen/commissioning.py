"""Bringing a CANopen CiA-402 drive up for the cyclic exchange, over SDO and NMT.

In order: make sure no other master drives the bus (no foreign SYNC, the drive not enabled
by someone else), reach the node (NMT reset communication and its boot-up, or an SDO answer),
check 0x1000 is a CiA-402 device, then **read what the drive has** before writing anything
(:mod:`drives.canopen.inventory`: the optional objects, the cyclic objects, its PDOs, their
sub-indices and how many entries each mapping holds).  A drive without an object the cycle
maps is refused; what the safety chain wants and the drive lacks is one warning per object
(:mod:`drives.canopen.safety_setup`), or a refusal under ``[safety] strict``, before any write.
Then: the cycle period 0x1006, the TPDOs and the RPDO(s) (:mod:`drives.canopen.pdo_plan`:
packed into 8-byte frames within each mapping's entries, else one object per PDO, else the
drive's default mapping; :mod:`drives.canopen.pdo_setup` writes them and falls back when the
drive refuses one, and the refusal is a note), the other PDOs invalidated, the scaling the drive
has, 0x6007 and 0x1016:01 written and read back, its heartbeat 0x1017, NMT start, and its
heartbeat showing OPERATIONAL.  Every write goes to an object the inventory found.

Scaling: what the drive states, :mod:`drives.canopen.stated_scaling` (the standard objects
0x6076, 0x6072 and the factor group where the drive has them, manufacturer objects only where an
EDS the user gave names them).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import NoReturn, cast

import canopen

from drives.base import ScalingReading
from drives.canopen.events import DriveEvents
from drives.canopen.inventory import DriveInventory, InventoryReader
from drives.canopen.pdo_codec import PdoCodec
from drives.canopen.pdo_plan import object_label, plans
from drives.canopen.pdo_setup import AppliedMapping, PdoSetup
from drives.canopen.safety_setup import missing_objects, refuse_if_strict, write_safety_objects
from drives.canopen.sdo import SdoAccess
from drives.canopen.stated_scaling import read_stated_scaling
from drives.cia301 import (
    COMMUNICATION_CYCLE_PERIOD,
    DEVICE_PROFILE_402,
    DEVICE_TYPE,
    PRODUCER_HEARTBEAT_TIME,
    RPDO_BASES,
    SYNC_COB_ID,
    TPDO_BASES,
    NmtCommand,
    NmtState,
)
from drives.cia402 import (
    STATUSWORD,
    DataType,
    ObjectSpec,
    State,
    decode_statusword,
)
from drives.errors import DriveError, DriveProtocolError, DriveRefusal, DriveTimeout
from drives.safety import SafetySettings

logger = logging.getLogger(__name__)



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
    """What commissioning found and set up: 0x1000, the TPDOs and RPDOs the cycle uses (codecs and
    COB-IDs, in order), the drive's scaling readings per field (in order of precedence) with notes
    on what its objects cannot give, one warning per object the drive lacks (unless ``strict``
    refused), a note per PDO mapping the drive refused, and the inventory it was all decided from."""

    device_type: int | None
    tpdo_codecs: tuple[PdoCodec, ...]
    tpdo_cobs: tuple[int, ...]
    rpdo_codecs: tuple[PdoCodec, ...]
    rpdo_cobs: tuple[int, ...]
    scaling: dict[str, tuple[ScalingReading, ...]]
    inventory: DriveInventory
    scaling_notes: tuple[str, ...] = ()
    safety_warnings: tuple[str, ...] = field(default_factory=tuple)
    mapping_notes: tuple[str, ...] = field(default_factory=tuple)


@dataclass
class Commissioning:
    """One commissioning run against ``node`` (see the module docstring)."""

    name: str
    node: canopen.RemoteNode
    sdo: SdoAccess
    events: DriveEvents
    settings: CommissioningSettings
    safety: SafetySettings

    def run(self, tpdo_objects: tuple[ObjectSpec, ...], rpdo_objects: tuple[ObjectSpec, ...], *,
            answered: bool = True) -> Commissioned:
        """Commission the drive for ``tpdo_objects`` (drive -> master, in order) and ``rpdo_objects``;
        ``answered``: what :meth:`refuse_another_master` returned (False: the drive left its SDO read
        unanswered, so no boot-up after the reset means it is not there)."""
        self._reach(answered)
        device_type = self._check_device_type() if self.settings.check_device_type else None
        inventory = InventoryReader(self.sdo).read((*tpdo_objects, *rpdo_objects))
        lacking = [spec for spec in (*tpdo_objects, *rpdo_objects) if not inventory.has(spec.index, spec.subindex)]
        if lacking:
            raise DriveProtocolError(self.name, "the drive lacks " + ", ".join(f"{object_label(s)} {s.name}" for s in lacking)
                                     + ": it cannot be driven in cyclic synchronous torque mode by this master")
        tpdo_plans, tpdo_skipped = plans(tpdo_objects, inventory.tpdos, exact=False, max_bytes=inventory.max_pdo_bytes)
        rpdo_plans, rpdo_skipped = plans(rpdo_objects, inventory.rpdos, exact=True, max_bytes=inventory.max_pdo_bytes)
        deadline_ms = self.safety.rpdo_deadline_ms(self.settings.period)
        first_rpdos = [frame.pdo for frame in rpdo_plans[0].frames] if rpdo_plans else []
        refuse_if_strict(self.name, self.safety,
                         missing_objects(inventory, self.safety, deadline_ms, self.settings.period, first_rpdos))
        if inventory.has(COMMUNICATION_CYCLE_PERIOD):
            self.sdo.write_int(COMMUNICATION_CYCLE_PERIOD, 0, DataType.UNSIGNED32, round(self.settings.period * 1e6))
        setup = PdoSetup(self.name, self.sdo, cast(int, self.node.id))  # canopen types it Optional; a RemoteNode has one
        tpdos = setup.apply(tpdo_plans, tpdo_skipped, TPDO_BASES)
        rpdos = setup.apply(rpdo_plans, rpdo_skipped, RPDO_BASES, deadline_ms)
        used = {frame.pdo for frame in (*tpdos.plan.frames, *rpdos.plan.frames)}
        for pdo in (*inventory.tpdos, *inventory.rpdos):
            if pdo not in used:
                setup.invalidate(pdo)
        rpdo_channels = [frame.pdo for frame in rpdos.plan.frames]
        missing = missing_objects(inventory, self.safety, deadline_ms, self.settings.period, rpdo_channels)
        refuse_if_strict(self.name, self.safety, missing)  # a fallback may use an RPDO without a deadline
        scaling, notes = self._read_scaling()
        write_safety_objects(self.name, self.sdo, inventory, self.safety, deadline_ms, rpdo_channels)
        for item in missing:
            logger.warning("%s: %s", self.name, item.warning)
        mapping_notes = (*self._mapping_notes("TPDO", tpdos), *self._mapping_notes("RPDO", rpdos))
        self._start(inventory)
        node = self.node.id
        return Commissioned(
            device_type,
            tuple(PdoCodec(f.objects, name=f"{f.pdo.label} of node {node}") for f in tpdos.plan.frames), tpdos.cob_ids,
            tuple(PdoCodec(f.objects, name=f"{f.pdo.label} of node {node}") for f in rpdos.plan.frames), rpdos.cob_ids,
            scaling, inventory, notes, tuple(item.warning for item in missing), mapping_notes,
        )

    def _mapping_notes(self, kind: str, applied: AppliedMapping) -> tuple[str, ...]:
        """A note (logged as a warning) for each mapping the drive refused, ending with the one in use."""
        if not applied.refusals:
            return ()
        notes = (*(f"{kind} mapping {refusal}" for refusal in applied.refusals),
                 f"{kind} mapping in use: {applied.plan.describe()}")
        for note in notes:
            logger.warning("%s: %s", self.name, note)
        return notes

    def refuse_another_master(self) -> bool:
        """Listen before taking the bus: a SYNC from someone else, or the drive enabled by someone
        else, means another master is at work; refuse rather than reset the drive under it.  Whether
        the drive answered the SDO read of its statusword (within ``boot_timeout``)."""
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
        return self._refuse_an_enabled_drive()

    def _refuse_an_enabled_drive(self) -> bool:
        """A drive already in OPERATION ENABLED is driven by someone else (this master always
        leaves it disabled, and the drive's own watchdog stops it when a master dies).  Asked
        before the NMT reset, which would itself abort that connection.  Whether it answered (an SDO abort, as a
        device without 0x6041 sends, is an answer)."""
        sdo = self.node.sdo
        saved = sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES
        sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = self.settings.boot_timeout, 1
        try:
            state = decode_statusword(self.sdo.read_int(STATUSWORD.index, 0, DataType.UNSIGNED16))
        except DriveTimeout:
            return False  # no answer (yet): reaching the node says why
        except DriveError:
            return True  # an abort or a malformed answer is an answer: not a CiA-402 drive, 0x1000 will say
        finally:
            sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = saved
        if state is State.OPERATION_ENABLED:
            raise DriveError(
                self.name,
                "the drive is in OPERATION ENABLED before this master enabled it: another master drives it "
                "(without SYNC); stop that master, or disable the drive, before starting this one",
            )
        return True

    def _reach(self, answered: bool) -> None:
        """Reset communication and wait for the boot-up message, or for an SDO answer.  A drive that
        left the SDO read before the reset unanswered (``answered`` False) and sends no boot-up after
        it is not asked again: a drive that ignores the reset is in the state it was, silent to SDO
        (a third wait of ``boot_timeout`` made a missing drive take three times the time its error named)."""
        timeout = self.settings.boot_timeout
        how = "NMT reset communication"
        self.events.forget_state()
        if self.settings.reset_communication:
            self.node.nmt.send_command(NmtCommand.RESET_COMMUNICATION)
            if self.events.wait_for_state(NmtState.BOOT_UP, timeout):
                return
            if not answered:
                self._unreached(f"no SDO answer within {timeout:.3g} s before NMT reset communication and no boot-up "
                                f"within {timeout:.3g} s after it")
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
        except DriveRefusal:
            return  # it answered
        except DriveTimeout:
            pass
        finally:
            sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = saved
        self._unreached(f"no boot-up after {how} and no SDO answer within {timeout:.3g} s")

    def _unreached(self, what: str) -> NoReturn:
        """DriveTimeout: ``what`` the node did not do, what to check, and the nodes heard meanwhile."""
        seen = sorted(n for n in self.node.network.scanner.nodes if n != self.node.id)
        hint = f"; nodes seen on the bus: {', '.join(map(str, seen))}" if seen else "; no other node seen on the bus"
        raise DriveTimeout(self.name, f"{what} (check node id {self.node.id}, bitrate, wiring{hint})")

    def _check_device_type(self) -> int:
        device_type = self.sdo.read_int(DEVICE_TYPE, 0, DataType.UNSIGNED32)
        if device_type & 0xFFFF != DEVICE_PROFILE_402:
            raise DriveProtocolError(
                self.name,
                f"0x1000 device type = 0x{device_type:08X} is not a CiA-402 drive "
                f"(profile {device_type & 0xFFFF}, expected {DEVICE_PROFILE_402})",
            )
        return device_type

    def _read_scaling(self) -> tuple[dict[str, tuple[ScalingReading, ...]], tuple[str, ...]]:
        """The scaling the drive states (:func:`drives.canopen.stated_scaling.read_stated_scaling`)."""
        return read_stated_scaling(self.name, self.sdo, self.node.object_dictionary)

    def _start(self, inventory: DriveInventory) -> None:
        """Heartbeat 0x1017 (if the drive has it), NMT start, and its heartbeat showing OPERATIONAL."""
        producer_ms = self.settings.heartbeat_producer_ms if inventory.has(PRODUCER_HEARTBEAT_TIME) else 0
        if inventory.has(PRODUCER_HEARTBEAT_TIME):
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
