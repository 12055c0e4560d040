"""The controller as a CANopen node: gated wall uploads over SDO.

Object dictionary (manufacturer area), generated from the running scene:

=========  ===  =============  ====  =============================================
index      sub  type           acc.  meaning
=========  ===  =============  ====  =============================================
0x2000     0    UNSIGNED8      ro    number of scene objects ``n``
0x2001     0    UNSIGNED8      wo    commit: write 1 to pass the staged K/B through the gate
0x2002     0    VISIBLE_STRING ro    the last commit's outcome ("accepted ..." or the reason)
0x2100+i   1    REAL64         rw    object ``i``'s stiffness K, N/m (reads: the running value)
0x2100+i   2    REAL64         rw    object ``i``'s damping B, N s/m (reads: the running value)
0x2100+i   3    VISIBLE_STRING ro    object ``i``'s name
=========  ===  =============  ====  =============================================

Writes to sub 1/2 only stage values; a commit judges the whole staged set with the gate and
either stages it for the controller's next cycle boundary or answers with SDO abort
0x06090030 (invalid value), logs the reason, keeps it at 0x2002, and drops the staged
values: a refused commit leaves the running scene exactly as it was.  The node has its own
bus handle and network, so SDO traffic and the gate run outside the control thread.
"""

from __future__ import annotations

import logging
import struct
from typing import Any, Mapping

import canopen
from canopen import LocalNode, SdoAbortedError
from canopen.objectdictionary import ODRecord, ODVariable, ObjectDictionary, datatypes

from haptic_bus.control.controller import WallController
from drives.errors import HapticBusError

logger = logging.getLogger(__name__)

OBJECT_COUNT = 0x2000
COMMIT = 0x2001
LAST_RESULT = 0x2002
WALL_BASE = 0x2100
SUB_STIFFNESS, SUB_DAMPING, SUB_NAME = 1, 2, 3
ABORT_INVALID_VALUE = 0x06090030
_REAL64 = struct.Struct("<d")


def _variable(name: str, index: int, subindex: int, data_type: int, access: str) -> ODVariable:
    var = ODVariable(name, index, subindex)
    var.data_type = data_type
    var.access_type = access
    return var


def controller_dictionary(names: list[str]) -> ObjectDictionary:
    """The controller node's object dictionary for scene objects ``names`` (in order)."""
    od = ObjectDictionary()
    device_type = _variable("Device type", 0x1000, 0, datatypes.UNSIGNED32, "ro")
    device_type.default = 0
    od.add_object(device_type)
    od.add_object(_variable("Number of scene objects", OBJECT_COUNT, 0, datatypes.UNSIGNED8, "ro"))
    od.add_object(_variable("Commit wall parameters", COMMIT, 0, datatypes.UNSIGNED8, "wo"))
    od.add_object(_variable("Last commit result", LAST_RESULT, 0, datatypes.VISIBLE_STRING, "ro"))
    for i, name in enumerate(names):
        record = ODRecord(f"Scene object {i}", WALL_BASE + i)
        count = _variable("Highest sub-index", WALL_BASE + i, 0, datatypes.UNSIGNED8, "ro")
        count.default = 3
        record.add_member(count)
        record.add_member(_variable("Stiffness K (N/m)", WALL_BASE + i, SUB_STIFFNESS, datatypes.REAL64, "rw"))
        record.add_member(_variable("Damping B (N s/m)", WALL_BASE + i, SUB_DAMPING, datatypes.REAL64, "rw"))
        record.add_member(_variable("Name", WALL_BASE + i, SUB_NAME, datatypes.VISIBLE_STRING, "ro"))
        od.add_object(record)
    return od


class ControllerNode:
    """Serves ``controller``'s wall parameters as CANopen node ``node_id`` on its own bus handle.

    ``bus``: python-can keyword arguments (``{"interface": ..., "channel": ...}``), opened here.
    """

    def __init__(self, controller: WallController, node_id: int, bus: Mapping[str, Any]) -> None:
        if not 1 <= node_id <= 127:
            raise HapticBusError(f"controller node id {node_id!r} is invalid; allowed: 1..127")
        self.controller = controller
        self.node_id = node_id
        self._names = [obj.name for obj in controller.scene.objects]
        self._staged: dict[int, list[float | None]] = {}
        self.last_result = "no commit yet"
        self.accepted = 0
        self.refused = 0
        self._bus_config = dict(bus)
        self._network = canopen.Network()
        self._node = LocalNode(node_id, controller_dictionary(self._names))
        self._node.add_read_callback(self._on_read)
        self._node.add_write_callback(self._on_write)

    def start(self) -> None:
        """Open the bus and answer SDO requests (in canopen's notifier thread)."""
        self._network.connect(**self._bus_config)
        self._network.add_node(self._node)
        self._node.nmt.state = "OPERATIONAL"

    def stop(self) -> None:
        """Stop answering and close the bus handle."""
        self._network.disconnect()

    def __enter__(self) -> "ControllerNode":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _on_read(self, index: int, subindex: int, od: ODVariable) -> Any:
        if index == OBJECT_COUNT:
            return len(self._names)
        if index == LAST_RESULT:
            return self.last_result
        i = index - WALL_BASE
        if 0 <= i < len(self._names) and subindex in (SUB_STIFFNESS, SUB_DAMPING, SUB_NAME):
            obj = self.controller.scene.by_name()[self._names[i]]
            return {SUB_STIFFNESS: obj.stiffness, SUB_DAMPING: obj.damping, SUB_NAME: obj.name}[subindex]
        return None

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        i = index - WALL_BASE
        if 0 <= i < len(self._names) and subindex in (SUB_STIFFNESS, SUB_DAMPING):
            (value,) = _REAL64.unpack(data)
            self._staged.setdefault(i, [None, None])[subindex - 1] = value
        elif index == COMMIT:
            if data[0] != 1:
                raise SdoAbortedError(ABORT_INVALID_VALUE)
            self._commit()

    def _commit(self) -> None:
        staged, self._staged = self._staged, {}
        try:
            for i, (K, B) in sorted(staged.items()):
                current = self.controller.latest_scene.by_name()[self._names[i]]
                K = current.stiffness if K is None else K
                B = current.damping if B is None else B
                staged[i] = [K, B]
            decision = self.controller.set_walls({self._names[i]: (K, B) for i, (K, B) in staged.items()})
        except HapticBusError as error:  # GateRefusal or an invalid value (NaN, negative, ...)
            self.refused += 1
            self.last_result = f"refused: {error}"
            logger.warning("node %d: commit %s", self.node_id, self.last_result)
            raise SdoAbortedError(ABORT_INVALID_VALUE) from error
        self.accepted += 1
        worst = decision.worst_margin
        self.last_result = "accepted" + ("" if worst is None else f": worst margin {worst:.4g} N s/m")
        logger.info("node %d: commit %s", self.node_id, self.last_result)


def upload_walls(
    bus: Mapping[str, Any], node_id: int, changes: Mapping[int, tuple[float, float]], timeout: float = 1.0
) -> str:
    """Write ``{object index: (K, B)}`` to a running controller and commit; return its verdict.

    Raises :class:`canopen.SdoAbortedError` (0x06090030) when the gate refuses; the message is
    then at 0x2002, which this function reads and attaches as ``error.reason``.
    """
    network = canopen.Network()
    network.connect(**dict(bus))
    try:
        node = network.add_node(canopen.RemoteNode(node_id, controller_dictionary([])))
        node.sdo.RESPONSE_TIMEOUT = timeout
        for i, (K, B) in changes.items():
            node.sdo.download(WALL_BASE + i, SUB_STIFFNESS, _REAL64.pack(K))
            node.sdo.download(WALL_BASE + i, SUB_DAMPING, _REAL64.pack(B))
        try:
            node.sdo.download(COMMIT, 0, b"\x01")
        except SdoAbortedError as error:
            error.reason = node.sdo.upload(LAST_RESULT, 0).decode(errors="replace")
            raise
        return node.sdo.upload(LAST_RESULT, 0).decode(errors="replace")
    finally:
        network.disconnect()
