"""The controller as a CANopen node: gated wall uploads over SDO.

Object dictionary, generated from the running scene:

=========  ===  =============  ====  =============================================
index      sub  type           acc.  meaning
=========  ===  =============  ====  =============================================
0x1000     0    UNSIGNED32     ro    device type: 0 (no device profile)
0x1001     0    UNSIGNED8      ro    error register: bit 0 once the run stopped on an error
0x1017     0    UNSIGNED16     ro    producer heartbeat time, ms (the master's, set by the profile)
0x1018     1-4  UNSIGNED32     ro    identity: vendor 0, product "HBUS", revision, serial 0
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
bus handle and network, so SDO traffic and the gate run outside the control thread.  Its
boot-up and heartbeat come from the CANopen master of the same process
(:class:`drives.canopen.heartbeat.HeartbeatProducer`, node id ``SafetySettings.master_node_id``),
which is the same node seen from the bus; a sub-index on a single-value object is refused
with abort 0x06090011.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Mapping
from typing import Any

import canopen
from canopen import SdoAbortedError
from canopen.objectdictionary import ObjectDictionary, ODRecord, ODVariable, datatypes

from drives.bus_config import open_bus
from drives.canopen.link import ReceiveErrors, shut_down
from drives.canopen.local_node import StrictLocalNode
from drives.cia301 import NMT_COB_ID, SDO_RX_BASE
from drives.udp_multicast import standard_filters
from haptic_bus._version import __version__
from haptic_bus.control.controller import WallController
from haptic_bus.errors import HapticBusError
from haptic_bus.validation import whole_in_range

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


PRODUCT_CODE = 0x48425553  # "HBUS"


def _constant(name: str, index: int, subindex: int, data_type: int, value: int) -> ODVariable:
    var = _variable(name, index, subindex, data_type, "ro")
    var.default = value
    return var


def controller_dictionary(names: list[str], heartbeat_ms: int = 0) -> ObjectDictionary:
    """The controller node's object dictionary for scene objects ``names`` (in order)."""
    od = ObjectDictionary()
    od.add_object(_constant("Device type", 0x1000, 0, datatypes.UNSIGNED32, 0))
    od.add_object(_constant("Error register", 0x1001, 0, datatypes.UNSIGNED8, 0))
    od.add_object(_constant("Producer heartbeat time", 0x1017, 0, datatypes.UNSIGNED16, heartbeat_ms))
    identity = ODRecord("Identity object", 0x1018)
    major, minor, *_ = (int(part) for part in [*__version__.split("."), "0", "0"])
    for sub, name, value in ((0, "Highest sub-index supported", 4), (1, "Vendor-ID", 0), (2, "Product code", PRODUCT_CODE),
                             (3, "Revision number", major << 16 | minor), (4, "Serial number", 0)):
        identity.add_member(_constant(name, 0x1018, sub, datatypes.UNSIGNED8 if sub == 0 else datatypes.UNSIGNED32, value))
    od.add_object(identity)
    od.add_object(_variable("Number of scene objects", OBJECT_COUNT, 0, datatypes.UNSIGNED8, "ro"))
    od.add_object(_variable("Commit wall parameters", COMMIT, 0, datatypes.UNSIGNED8, "wo"))
    od.add_object(_variable("Last commit result", LAST_RESULT, 0, datatypes.VISIBLE_STRING, "ro"))
    for i in range(len(names)):  # the Name sub-index is answered by the read callback
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

    def __init__(self, controller: WallController, node_id: int, bus: Mapping[str, Any], heartbeat_ms: int = 0) -> None:
        self.controller = controller
        self.node_id = whole_in_range("controller node id", node_id, 1, 127)
        self._names = [obj.name for obj in controller.scene.objects]
        self._staged: dict[int, list[float | None]] = {}
        self.last_result = "no commit yet"
        self.accepted = 0
        self.refused = 0
        self._bus_config = dict(bus)
        self._network = canopen.Network()
        self._node = StrictLocalNode(node_id, controller_dictionary(self._names, heartbeat_ms))
        self._node.add_read_callback(self._on_read)
        self._node.add_write_callback(self._on_write)

    def start(self) -> None:
        """Open the bus and answer SDO requests (in canopen's notifier thread, which a receive
        error does not end: it is counted and logged)."""
        self._network.listeners.append(ReceiveErrors(f"controller node {self.node_id}"))  # type: ignore[arg-type]  # a can.Listener, as python-can wants
        bus = self._network.bus = open_bus(**self._bus_config)
        # SDO requests to this node and NMT commands only: on udp_multicast the other frames of a
        # 1 kHz loop are dropped before they are decoded (drives.udp_multicast), not in this process's Python
        bus.set_filters(standard_filters({SDO_RX_BASE + self.node_id, NMT_COB_ID}))
        self._network.connect()
        self._network.add_node(self._node)
        self._node.nmt.state = "OPERATIONAL"

    def stop(self) -> None:
        """Stop answering and close the bus handle."""
        self._node.remove_network()
        shut_down(self._network, f"controller node {self.node_id}")

    def __enter__(self) -> ControllerNode:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _on_read(self, index: int, subindex: int, od: ODVariable) -> Any:
        if index == 0x1001:
            return 0x01 if self.controller.stopped_on_error else 0
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
            current = self.controller.latest_scene.by_name()
            walls: dict[str, tuple[float, float]] = {}
            for i, (K, B) in sorted(staged.items()):  # a half-written pair keeps the scene's other value
                wall = current[self._names[i]]
                walls[self._names[i]] = (wall.stiffness if K is None else K, wall.damping if B is None else B)
            decision = self.controller.set_walls(walls)
        except HapticBusError as error:  # Refusal or an invalid value (NaN, negative, ...)
            self.refused += 1
            self.last_result = f"refused: {error}"
            logger.warning("node %d: commit %s", self.node_id, self.last_result)
            raise SdoAbortedError(ABORT_INVALID_VALUE) from error
        self.accepted += 1
        worst = decision.worst_margin
        self.last_result = "accepted" + ("" if worst is None else f": worst margin {worst:.4g} N s/m")
        logger.info("node %d: commit %s", self.node_id, self.last_result)
