"""``haptic-bus upload``'s side: change a running controller's walls over SDO, gated by its node.

The client asks before it writes: 0x1000 and 0x1018:02 say whether the node is a haptic-bus
controller (device type 0, product code "HBUS", :mod:`haptic_bus.node.controller_node`), 0x2000 how many
scene objects it has; only then are the staged K and B written (0x2100 + i, sub 1 and 2) and
committed (0x2001), and the verdict read (0x2002).  What can go wrong, each its own error with
one line to say:

- nobody answers on the node within the timeout: a ``DriveTimeout`` asking whether a run is going on;
- another device answers (a drive's node id given instead of the controller's):
  a ``DriveError``, naming its 0x1000 (and 0x1018:02);
- an object index the controller does not have: a ``ParameterError`` (nothing was written);
- the gate refuses: a ``Refusal``, with the abort code and the reason the node keeps at 0x2002.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from typing import Any

import canopen
from can.interfaces.virtual import VirtualBus

from drives.bus_config import open_bus
from drives.canopen.link import NOTIFIER_CYCLE, ReceiveErrors, shut_down
from drives.canopen.scan import device_kind
from drives.canopen.sdo import SdoAccess
from drives.cia301 import DEVICE_TYPE, IDENTITY, SDO_TX_BASE, SdoAbort, sdo_abort_text
from drives.cia402 import DataType
from drives.udp_multicast import standard_filters
from haptic_bus.errors import DriveError, DriveRefusal, DriveTimeout, ParameterError, Refusal
from haptic_bus.node.controller_node import (
    COMMIT,
    LAST_RESULT,
    OBJECT_COUNT,
    PRODUCT_CODE,
    SUB_DAMPING,
    SUB_NAME,
    SUB_STIFFNESS,
    WALL_BASE,
    controller_dictionary,
)

_REAL64 = struct.Struct("<d")
JUDGE_WAIT = 30.0
"""s: the least a commit (0x2001) waits for its answer, which the node sends once the gate's verdict
is in: a three-axis scene's coupled gate took 3-8 s in the judge process on a loaded 2-core machine,
and a client that gave up after the 1 s of the other transfers reported a failure for an upload the
run then adopted."""
_NAMES_SHOWN = 8  # object names listed when an index is refused


def _device_type(sdo: SdoAccess, node_id: int, timeout: float, alone: bool) -> int:
    """0x1000 of the node: DriveTimeout if silent (``alone``: on a bus that reaches this process only,
    which it says), DriveError if it aborts the read."""
    try:
        return sdo.read_int(DEVICE_TYPE, 0, DataType.UNSIGNED32)
    except DriveRefusal as error:
        raise DriveError(f"node {node_id}", f"node {node_id} answered, but not as a haptic-bus controller "
                                            f"(reading 0x1000: {sdo_abort_text(error.code)})") from None
    except DriveTimeout:
        where = ("; python-can's virtual bus reaches this process alone: a run in another process is never on it"
                 if alone else "")
        raise DriveTimeout(f"node {node_id}", f"no controller answered on node {node_id} within {timeout:g} s (is "
                                              f"haptic-bus run going on this bus with --controller-node-id {node_id}?"
                                              f"{where})") from None


def check_controller(sdo: SdoAccess, node_id: int, timeout: float, alone: bool = False) -> int:
    """The number of scene objects of the controller on ``node_id``, once 0x1000 and 0x1018:02 show it is one
    (``alone``: the bus reaches this process only, python-can's virtual one)."""
    device_type = _device_type(sdo, node_id, timeout, alone)
    if device_type != 0:
        role = "a drive" if device_type & 0xFFFF == 402 else "another device"
        raise DriveError(f"node {node_id}", f"node {node_id} answered as {role}, not a haptic-bus controller "
                                                f"(0x1000 = 0x{device_type:08X}: {device_kind(device_type)})")
    try:
        product = sdo.read_int(IDENTITY, 2, DataType.UNSIGNED32)
    except DriveRefusal:
        product = None
    if product != PRODUCT_CODE:
        said = "no 0x1018:02" if product is None else f"0x1018:02 = 0x{product:08X}"
        raise DriveError(f"node {node_id}", f"node {node_id} answered, but not as a haptic-bus controller "
                                                f"(0x1000 = 0, {said}, a controller's is 0x{PRODUCT_CODE:08X} 'HBUS')")
    return sdo.read_int(OBJECT_COUNT, 0, DataType.UNSIGNED8)


def _refuse_unknown_objects(sdo: SdoAccess, node_id: int, count: int, indices: list[int]) -> None:
    """ParameterError for the first index not below ``count``, listing the objects the controller has."""
    missing = [i for i in indices if not 0 <= i < count]
    if not missing:
        return
    if count == 0:
        raise ParameterError("--object", missing[0], f"an object of the running scene; controller node {node_id} has none",
                             "upload")
    names = [f"{i} {sdo.upload(WALL_BASE + i, SUB_NAME).decode(errors='replace')!r}" for i in range(min(count, _NAMES_SHOWN))]
    listing = ", ".join(names) + (", ..." if count > _NAMES_SHOWN else "")
    raise ParameterError("--object", missing[0], f"an object of the running scene, 0..{count - 1} (controller node "
                                               f"{node_id} has {count} object{'s' if count > 1 else ''}: {listing})", "upload")


def upload_walls(
    bus: Mapping[str, Any], node_id: int, changes: Mapping[int, tuple[float, float]], timeout: float = 1.0
) -> str:
    """Write ``{object index: (K, B)}`` to the running controller on ``node_id`` and commit; its verdict.
    ``timeout`` (s) bounds each SDO answer but the commit's, which waits for the gate's verdict
    (at least :data:`JUDGE_WAIT`); a commit answered is an upload accepted, even when the run ends
    before the verdict's text (0x2002) is read.

    ``bus``: python-can keyword arguments (python-can's configuration fills in the rest, as for
    every bus here).  Raises (module docstring) :class:`DriveTimeout` (no controller), :class:`DriveError`
    (not a controller), :class:`ParameterError` (before any write) or :class:`Refusal`.
    """
    link = open_bus(**dict(bus))
    link.set_filters(standard_filters({SDO_TX_BASE + node_id}))  # its SDO answers alone: on udp_multicast a
    network = canopen.Network(link)  # run's traffic is then dropped before it is decoded
    network.NOTIFIER_CYCLE = NOTIFIER_CYCLE  # canopen's 1 s recv block kept the command up to 1 s past its answer
    network.listeners.append(ReceiveErrors("upload"))  # type: ignore[arg-type]  # a can.Listener, as python-can wants
    network.connect()
    try:
        dictionary = canopen.ObjectDictionary()
        node = network.add_node(canopen.RemoteNode(node_id, dictionary))
        sdo = SdoAccess(f"controller node {node_id}", node, timeout, lambda: None)
        count = check_controller(sdo, node_id, timeout, alone=isinstance(link, VirtualBus))
        _refuse_unknown_objects(sdo, node_id, count, sorted(changes))
        walls = controller_dictionary([""] * count)  # the objects written: an SDO error names "Scene object i.Stiffness K (N/m)"
        for i in changes:
            dictionary.add_object(walls[WALL_BASE + i])
        try:
            for i, (K, B) in changes.items():
                sdo.download(WALL_BASE + i, SUB_STIFFNESS, _REAL64.pack(K))
                sdo.download(WALL_BASE + i, SUB_DAMPING, _REAL64.pack(B))
            with sdo.waiting(max(timeout, JUDGE_WAIT)):  # answered once the gate's verdict is in
                sdo.download(COMMIT, 0, b"\x01")
        except DriveRefusal as error:
            reason = (sdo.upload(LAST_RESULT, 0).decode(errors="replace") if error.code == SdoAbort.VALUE_RANGE
                      else error.message)
            raise Refusal(f"controller node {node_id} refused the upload (abort 0x{error.code:08X}): {reason}",
                          (reason,)) from None
        try:
            return sdo.upload(LAST_RESULT, 0).decode(errors="replace")
        except DriveTimeout:  # the commit was answered, so accepted: the run ended before its margin was read
            return "accepted (the run ended before its margin could be read)"
    finally:
        shut_down(network, "upload")
