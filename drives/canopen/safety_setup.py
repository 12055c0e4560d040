"""The drive's side of the safety chain (DESIGN 4.1) as far as the drive has it.

From the inventory (:mod:`drives.canopen.inventory`), before anything is written:
:func:`missing_objects` names each object the settings want and the drive lacks, with what is
then not protected.  The safety chain proper -- the heartbeat consumer 0x1016, the abort
connection option code 0x6007, the RPDO deadline 0x1400+n:05 of each RPDO the cycle uses --
is refused under ``[safety] strict`` (:func:`refuse_if_strict`); without ``strict`` each
missing object is one warning.  The drive's heartbeat producer 0x1017 and the cycle period
0x1006 are warned about only: the master still sees a silent drive through its missing TPDOs.

:func:`write_safety_objects` then writes 0x6007 and 0x1016:01 where the drive has them and
reads each back, with the RPDO deadlines (written with the mapping).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from drives.canopen.inventory import DriveInventory, DrivePdo
from drives.canopen.sdo import SdoAccess
from drives.cia301 import COMMUNICATION_CYCLE_PERIOD, CONSUMER_HEARTBEAT_TIME, PDO_EVENT_TIMER, PRODUCER_HEARTBEAT_TIME
from drives.cia402 import ABORT_CONNECTION_OPTION_CODE, AbortConnectionOption, DataType
from drives.errors import DriveProtocolError
from drives.safety import SafetySettings

ABORT_OPTION = ABORT_CONNECTION_OPTION_CODE.index


@dataclass(frozen=True)
class MissingObject:
    """An object the master wants and the drive lacks: ``label`` ("0x1016", "0x1400:05"), what is
    then not protected, and whether it belongs to the safety chain (``strict`` refuses those)."""

    label: str
    consequence: str
    chain: bool = True

    @property
    def warning(self) -> str:
        """"0x1016 absent: the drive will not stop on the controller's heartbeat loss"."""
        return f"{self.label} absent: {self.consequence}"


def missing_objects(inventory: DriveInventory, safety: SafetySettings, deadline_ms: int, period: float,
                    rpdos: Sequence[DrivePdo]) -> list[MissingObject]:
    """What the drive lacks of what ``safety`` (and the cycle, period ``period`` s, RPDO deadline
    ``deadline_ms`` ms on ``rpdos``) wants, in the order the warnings are given."""
    missing = []
    if safety.master_node_id is not None and not inventory.has(CONSUMER_HEARTBEAT_TIME, 1):
        missing.append(MissingObject("0x1016", "the drive will not stop on the controller's heartbeat loss"))
    if not inventory.has(ABORT_OPTION):
        reaction = AbortConnectionOption(safety.abort_option).name.lower().replace("_", " ")
        missing.append(MissingObject("0x6007", f"the drive's reaction to a lost connection cannot be set to "
                                               f"{reaction}; it keeps its own, which may be none"))
    if deadline_ms:
        for pdo in rpdos:
            if not pdo.has_event_timer:
                missing.append(MissingObject(
                    f"0x{pdo.communication:04X}:05",
                    f"the drive will not stop when the controller's torque targets ({pdo.label}) stop arriving "
                    "(no RPDO deadline)"))
    if not inventory.has(PRODUCER_HEARTBEAT_TIME):
        missing.append(MissingObject("0x1017", "the drive sends no heartbeat: the controller notices a silent drive "
                                               "only by its missing TPDOs", chain=False))
    if not inventory.has(COMMUNICATION_CYCLE_PERIOD):
        missing.append(MissingObject("0x1006", f"the drive is not told the cycle period ({period * 1e3:.6g} ms): set "
                                               "its cycle time to match by the vendor's means", chain=False))
    return missing


def refuse_if_strict(name: str, safety: SafetySettings, missing: Sequence[MissingObject]) -> None:
    """DriveProtocolError naming every missing safety-chain object, under the strict policy."""
    chain = [m for m in missing if m.chain]
    if safety.strict and chain:
        lacks = ", ".join(f"{m.label} ({m.consequence})" for m in chain)
        raise DriveProtocolError(name, f"refused under the strict safety policy ([safety] strict = true): "
                                       f"the drive lacks {lacks}")


def write_safety_objects(name: str, sdo: SdoAccess, inventory: DriveInventory, safety: SafetySettings,
                         deadline_ms: int, rpdos: Sequence[DrivePdo]) -> None:
    """0x6007 and 0x1016:01 written and read back where the drive has them, and the RPDO
    deadline of each RPDO in ``rpdos`` that has one read back; DriveProtocolError on a mismatch."""
    wanted: list[tuple[int, int, DataType, int, str]] = []
    if inventory.has(ABORT_OPTION):
        wanted.append((ABORT_OPTION, 0, DataType.INTEGER16, safety.abort_option, "0x6007 abort connection option code"))
    if safety.master_node_id is not None and inventory.has(CONSUMER_HEARTBEAT_TIME, 1):
        entry = safety.master_node_id << 16 | safety.consumer_ms
        wanted.append((CONSUMER_HEARTBEAT_TIME, 1, DataType.UNSIGNED32, entry, "0x1016:01 consumer heartbeat time"))
    for index, subindex, data_type, value, what in wanted:
        sdo.write_int(index, subindex, data_type, value)
        got = sdo.read_int(index, subindex, data_type)
        if got != value:
            raise DriveProtocolError(name, f"{what} reads back {got} after writing {value}")
    for pdo in rpdos:
        if deadline_ms and pdo.has_event_timer:
            got = sdo.read_int(pdo.communication, PDO_EVENT_TIMER, DataType.UNSIGNED16)
            if got != deadline_ms:
                raise DriveProtocolError(name, f"0x{pdo.communication:04X}:05 {pdo.label} event timer reads back "
                                               f"{got} ms after writing {deadline_ms}")
