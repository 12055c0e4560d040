"""An ``[[axes]]`` table's bus address, read once for the controller and the simulated drive: ``node_id``
(CANopen, :data:`~drives.cia301.NODE_ID_RANGE`) **or** ``unit_id`` (Modbus,
:data:`~drives.modbus.register_map.UNIT_ID_RANGE`), exactly one of them, in their tables' words."""

from __future__ import annotations

from drives.cia301 import NODE_ID_RANGE, NODE_IDS
from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS
from haptic_bus.profile.reader import Reader, profile_error

ONE_LINK = f"exactly one of node_id ({NODE_IDS}) and unit_id ({UNIT_IDS})"


def read_link(r: Reader) -> tuple[int | None, int | None]:
    """``(node_id, unit_id)`` of the axis table ``r`` reads, the one not given None; ParameterError naming the
    field for both or neither (a misspelt one, ``nod_id``, named as such) or an id out of its range."""
    if "node_id" not in r.table and "unit_id" not in r.table:
        for key in ("node_id", "unit_id"):
            r.refuse_misspelling(key, ONE_LINK)
    if ("node_id" in r.table) == ("unit_id" in r.table):
        raise profile_error(r.path, r.field("node_id"), r.table.get("node_id"), ONE_LINK)
    if "node_id" in r.table:
        return r.whole("node_id", *NODE_ID_RANGE, allowed=NODE_IDS), None
    return None, r.whole("unit_id", *UNIT_ID_RANGE, allowed=UNIT_IDS)
