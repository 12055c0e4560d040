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

Writes to sub 1/2 only stage values.  A commit hands the whole staged set to the gate in a
worker process (:mod:`~haptic_bus.node.verdicts`) and leaves the SDO download unanswered until
the verdict is in; whoever holds the verdict first answers it: the control thread, which looks
once a cycle without waiting (:meth:`ControllerNode.poll`, the run's ``on_cycle``), or, outside
the cycles, the thread that collects the worker's answers.  An accepted scene is staged for the
controller's next cycle boundary, never judged again; a refused one is answered with SDO abort
0x06090030 (invalid value), its reason logged and kept at 0x2002, the staged values dropped: a
refused commit leaves the running scene exactly as it was.  A commit while another is being
judged is refused at once (abort 0x08000022, device state).

The node is a canopen LocalNode on the drive's own network (:meth:`ControllerNode.attach`): one
bus handle for the process, its SDO requests dispatched by whoever reads the bus (the control
thread while it cycles) and its answers sent through the drive's link.  Its boot-up and heartbeat
come from the CANopen master of the same process (:class:`drives.canopen.heartbeat.HeartbeatProducer`,
node id ``SafetySettings.master_node_id``), which is the same node seen from the bus; a sub-index
on a single-value object is refused with abort 0x06090011.
"""

from __future__ import annotations

import contextlib
import logging
import struct
import threading
from collections.abc import Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

import canopen
from canopen import SdoAbortedError
from canopen.objectdictionary import ObjectDictionary, ODRecord, ODVariable, datatypes

from drives.canopen.local_node import DeferredDownloadServer, StrictLocalNode
from drives.cia301 import NODE_ID_RANGE, NODE_IDS
from haptic_bus._version import __version__
from haptic_bus.control.controller import WallController
from haptic_bus.control.protocols import Gate
from haptic_bus.control.scene_switch import SceneEntry
from haptic_bus.errors import HapticBusError
from haptic_bus.node.verdicts import Verdict, judge_pool, judge_walls, kill_workers
from haptic_bus.validation import whole_in_range

logger = logging.getLogger(__name__)

OBJECT_COUNT = 0x2000
COMMIT = 0x2001
LAST_RESULT = 0x2002
WALL_BASE = 0x2100
SUB_STIFFNESS, SUB_DAMPING, SUB_NAME = 1, 2, 3
ABORT_INVALID_VALUE = 0x06090030
ABORT_DEVICE_STATE = 0x08000022  # a commit while another is being judged
ABORT_GENERAL = 0x08000000  # the judge itself failed
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


@dataclass(frozen=True)
class _Judging:
    """A commit out for judgement: the worker's future, and the gate and latest scene it was judged against."""

    future: Future[Verdict]
    gate: Gate[Any, Any]
    base: SceneEntry[Any, Any]


class ControllerNode:
    """Serves ``controller``'s wall parameters as CANopen node ``node_id`` on the network it is
    attached to (:meth:`attach`; the drive's), its commits judged in a worker process (module
    docstring).  ``heartbeat_ms`` is what 0x1017 reads (the master's heartbeat)."""

    def __init__(self, controller: WallController, node_id: int, heartbeat_ms: int = 0) -> None:
        self.controller = controller
        self.node_id = whole_in_range("controller node id", node_id, *NODE_ID_RANGE, allowed=NODE_IDS)
        self._names = [obj.name for obj in controller.scene.objects]
        self._staged: dict[int, list[float | None]] = {}
        self.last_result = "no commit yet"
        self.accepted = 0
        self.refused = 0
        self._node = StrictLocalNode(node_id, controller_dictionary(self._names, heartbeat_ms))
        self._server = DeferredDownloadServer(self._node, node_id, COMMIT, self._commit)
        self._node.sdo = self._server  # before attaching: the network subscribes this server
        self._node.add_read_callback(self._on_read)
        self._node.add_write_callback(self._on_write)
        self._network: canopen.Network | None = None
        self._pool: ProcessPoolExecutor | None = None  # the judge worker, from attach()
        self._warming: Future[Verdict] | None = None  # attach()'s judgement of the running scene
        self._judging: _Judging | None = None
        self._verdict_in = False  # the worker answered; the next poll (or the collector) settles it
        self._cycling = False  # the control thread polls: it answers the verdict
        self._lock = threading.Lock()

    def attach(self, network: canopen.Network) -> None:
        """Answer SDO requests on ``network`` (the drive's), the judge worker started first and handed
        the running scene to judge once, not waited for: its imports are done for the first upload
        (a sphere in space: scipy.optimize, for the coupled gate's direction search), and the coupled
        gate brings the verdicts this process holds along (pickled with it), so they are not judged again."""
        self._pool = judge_pool()
        scenes = self.controller.scenes
        self._warming = self._pool.submit(judge_walls, scenes.gate, scenes.latest.scene, {})
        network.add_node(self._node)
        self._network = network
        self._node.nmt.state = "OPERATIONAL"

    def detach(self) -> None:
        """Stop answering (a commit still out for judgement stays unanswered: the client times out).
        Work handed to the judge worker that nobody waits for any more -- :meth:`attach`'s judgement
        of the running scene, a commit's -- is given up with the worker
        (:func:`~haptic_bus.node.verdicts.kill_workers`): a run stopped in its first seconds ends
        then, not once a sphere's direction search is done (the interpreter's exit waits for every
        task handed to a pool)."""
        network, self._network = self._network, None
        if network is not None and network.nodes.get(self.node_id) is self._node:
            del network[self.node_id]
        judging = self._judging
        handed = [self._warming, judging.future if judging is not None else None]
        if self._pool is not None and any(future is not None and not future.done() for future in handed):
            kill_workers(self._pool)

    @contextlib.contextmanager
    def attached(self, network: canopen.Network) -> Iterator[ControllerNode]:
        """:meth:`attach` to ``network`` for the ``with`` block, then :meth:`detach`."""
        self.attach(network)
        try:
            yield self
        finally:
            self.detach()

    @contextlib.contextmanager
    def cycling(self) -> Iterator[None]:
        """While the control thread cycles and calls :meth:`poll` every cycle, it answers verdicts."""
        with self._lock:
            self._cycling = True
        try:
            yield
        finally:
            with self._lock:
                self._cycling = False
                ready = self._verdict_in
            if ready:
                self._settle()

    def poll(self, _controller: object = None) -> None:
        """Once a cycle, from the control thread, never waiting: answer a verdict that is in."""
        if self._verdict_in:
            self._settle()

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
        elif index == COMMIT:  # a segmented commit (1 byte is always expedited): not a commit we judge
            raise SdoAbortedError(ABORT_INVALID_VALUE)

    def _commit(self, data: bytes) -> None:
        """A commit (0x2001 := 1): the staged walls out to the judge worker, the answer deferred."""
        if data[:1] != b"\x01":
            raise SdoAbortedError(ABORT_INVALID_VALUE)
        pool = self._pool
        if pool is None:  # not attached: nothing to judge with
            raise SdoAbortedError(ABORT_DEVICE_STATE)
        if self._judging is not None:
            raise SdoAbortedError(ABORT_DEVICE_STATE)
        staged, self._staged = self._staged, {}
        scenes = self.controller.scenes
        base = scenes.latest
        current = base.scene.by_name()
        walls: dict[str, tuple[float, float]] = {}
        for i, (K, B) in sorted(staged.items()):  # a half-written pair keeps the scene's other value
            wall = current[self._names[i]]
            walls[self._names[i]] = (wall.stiffness if K is None else K, wall.damping if B is None else B)
        try:
            future = pool.submit(judge_walls, scenes.gate, base.scene, walls)
        except (BrokenProcessPool, RuntimeError) as error:  # the worker died: no verdict to wait for
            raise SdoAbortedError(self._refuse(f"not judged: {error!r}", ABORT_GENERAL)) from error
        self._judging = _Judging(future, scenes.gate, base)
        future.add_done_callback(self._on_verdict)

    def _on_verdict(self, future: Future[Verdict]) -> None:
        """In the executor's collecting thread: the control thread answers while it cycles, else this thread."""
        with self._lock:
            self._verdict_in = True
            if self._cycling:
                return
        self._settle()

    def _settle(self) -> None:
        """Answer the commit whose verdict is in (from one thread only: the swap is locked)."""
        with self._lock:
            judging, self._judging = self._judging, None
            self._verdict_in = False
        if judging is None:
            return
        try:
            verdict = judging.future.result()
            if isinstance(verdict, str):
                raise HapticBusError(verdict)  # an invalid value (NaN, negative, ...)
            scene, decision = verdict
            self.controller.scenes.stage(scene, decision, (judging.gate, judging.base))
        except HapticBusError as error:  # Refusal (the gate's, or judged against an older scene) or an invalid value
            self._answer(self._refuse(f"refused: {error}", ABORT_INVALID_VALUE))
            return
        except Exception as error:  # the worker died or could not be reached: the commit is not judged
            self._answer(self._refuse(f"not judged: {error!r}", ABORT_GENERAL))
            return
        self.accepted += 1
        worst = decision.worst_margin
        self.last_result = "accepted" + ("" if worst is None else f": worst margin {worst:.4g} N s/m")
        logger.info("node %d: commit %s", self.node_id, self.last_result)
        self._answer(None)

    def _refuse(self, result: str, abort_code: int) -> int:
        """Count and log a refused commit, keep ``result`` at 0x2002; the SDO abort code to answer."""
        self.refused += 1
        self.last_result = result
        logger.log(logging.WARNING if abort_code == ABORT_INVALID_VALUE else logging.ERROR, "node %d: commit %s",
                   self.node_id, result)
        return abort_code

    def _answer(self, abort_code: int | None) -> None:
        """The commit's SDO answer, if the node is still on the bus (a bus gone: the client times out)."""
        if self._network is None:
            return
        try:
            self._server.answer(abort_code)
        except Exception as exc:  # any interface's send failure: the run goes on, the client times out
            logger.warning("node %d: could not answer the commit: %r", self.node_id, exc)
