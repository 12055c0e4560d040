"""The scene a running controller renders, and every change to it, each through the gate.

Uploads through the Python API are judged in the caller's thread and staged; an upload judged
elsewhere (the controller node's, in a worker process: the scene's ``with_walls`` builds the
changed scene there) is staged with its decision (:meth:`SceneSwitch.stage`), never judged again.  The control
loop adopts the last accepted one at a cycle boundary, whole, by reference (nothing is ever
cleared, so no upload can be lost between a read and a clear).
Every scene that is ever in effect gets an id; the history keeps its objects and the gate's
decision (what ``run.json`` reports).  A derate (the supervisor's) is adopted at once by the
control thread itself.

With ``beyond_gate`` (a ``bound`` passivity layer that guarantees passivity at run time, opted
into by the profile) a scene the gate refuses is admitted all the same: its decision, refused,
stays in the history and the event says so.

An upload that would put the handle inside an object it is not inside now (``step``: a wall
moved or added onto it, whose force it would then feel at once; the controller's
:meth:`~haptic_bus.control.controller.WallController.entered_step`) is refused, as a start inside
an object is: the gate judged the walls, not a jump onto the hand.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Generic

from haptic_bus.control.protocols import DecisionT, Gate, SceneT
from haptic_bus.control.record import EventLog
from haptic_bus.errors import Refusal


@dataclass(frozen=True)
class SceneEntry(Generic[SceneT, DecisionT]):
    """A scene that was in effect (or staged): its id, where it came from, the gate's decision."""

    scene_id: int
    origin: str
    scene: SceneT
    decision: DecisionT

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every object (its kind, geometry, K and B), and the gate's margin for each contact wall."""
        return {
            "scene_id": self.scene_id,
            "origin": self.origin,
            "objects": self.scene.object_dicts(),
            "walls": self.decision.wall_dicts(),
            "worst_margin": self.decision.worst_margin,
            "warnings": list(self.decision.warnings),
        }


class SceneSwitch(Generic[SceneT, DecisionT]):
    """Switches a running controller's scene, gated, at a cycle boundary: the running scene, the
    last accepted one, and their history (module docstring).  (Not :class:`~haptic_bus.control.scene.Slot`,
    a scene object: a box the handle is held inside.)

    ``gate``: the 1-D or the coupled gate (:class:`~haptic_bus.control.protocols.Gate`); ``now``
    gives the run's clock (s) for events; ``events`` receives "upload" and "refused";
    ``beyond_gate``: admit scenes the gate refuses (module docstring); ``step``: why a scene may
    not replace the running one where the handle is now (None: it may), or None for no such check.
    """

    def __init__(self, gate: Gate[SceneT, DecisionT], scene: SceneT, events: EventLog, now: Callable[[], float],
                 beyond_gate: bool = False, step: Callable[[SceneT, SceneT], str | None] | None = None) -> None:
        self.gate = gate
        self.events = events
        self.beyond_gate = beyond_gate
        self._step = step
        self._now = now
        self._lock = threading.Lock()
        first = SceneEntry(0, "profile", scene, self._decide(scene))
        self.history: list[SceneEntry[SceneT, DecisionT]] = [first]
        self.running = first
        self._latest = first
        self.applied = 0  # scenes adopted after the first

    @property
    def latest(self) -> SceneEntry[SceneT, DecisionT]:
        """The last accepted scene (running, or staged for the next cycle boundary)."""
        return self._latest

    def upload(self, scene: SceneT, origin: str = "upload") -> DecisionT:
        """Gate ``scene`` and stage it for the next cycle boundary; Refusal (logged) if refused."""
        with self._lock:
            return self._admit(scene, origin)

    def set_walls(self, changes: Mapping[str, tuple[float, float]], origin: str = "upload") -> DecisionT:
        """Change several objects' ``(K, B)`` (N/m, N s/m) as one upload: all pass the gate, or none applies."""
        with self._lock:
            return self._admit(self._latest.scene.with_walls(changes), origin)

    def stage(self, scene: SceneT, decision: DecisionT, judged: tuple[Gate[SceneT, DecisionT], SceneEntry[SceneT, DecisionT]],
              origin: str = "upload") -> DecisionT:
        """Stage ``scene`` with the ``decision`` a judge elsewhere gave (never judged again here), as
        :meth:`upload` would; ``judged``: the gate and the latest entry it was judged against, still
        both current, else :class:`~haptic_bus.errors.Refusal` (a derate or another upload came in
        between: upload again).  Refusal (logged) if the gate refused it."""
        with self._lock:
            gate, base = judged
            if gate is not self.gate or base is not self._latest:
                what = "the gate (a derate)" if gate is not self.gate else f"the scene (now scene {self._latest.scene_id})"
                self.events.add(self._now(), "refused", f"{origin} judged against a scene no longer the latest")
                raise Refusal(f"{what} changed while the {origin} was judged; upload again")
            if not decision.accepted and not self.beyond_gate:
                self.events.add(self._now(), "refused", f"{origin} refused by the gate", reasons=list(decision.reasons))
                raise Refusal.by_gate(decision)
            return self._stage(scene, decision, origin)

    def _decide(self, scene: SceneT) -> DecisionT:
        """The gate's decision; the gate's Refusal for a refused scene unless beyond the gate is allowed."""
        return self.gate.judge(scene) if self.beyond_gate else self.gate.admit(scene)

    def _admit(self, scene: SceneT, origin: str) -> DecisionT:
        try:
            decision = self._decide(scene)
        except Refusal as refusal:
            self.events.add(self._now(), "refused", f"{origin} refused by the gate", reasons=list(refusal.reasons))
            raise
        return self._stage(scene, decision, origin)

    def _stage(self, scene: SceneT, decision: DecisionT, origin: str) -> DecisionT:
        step = self._step(self.running.scene, scene) if self._step is not None else None
        if step is not None:
            self.events.add(self._now(), "refused", f"{origin} refused: {step}")
            raise Refusal(step)
        entry = SceneEntry(len(self.history), origin, scene, decision)
        self.history.append(entry)
        self._latest = entry
        beyond = "" if decision.accepted else " beyond the gate (the bound passivity layer holds it passive)"
        self.events.add(self._now(), "upload", f"{origin} accepted as scene {entry.scene_id}{beyond}",
                        scene_id=entry.scene_id, worst_margin=decision.worst_margin, gate_passed=decision.accepted)
        return decision

    def adopt(self) -> SceneEntry[SceneT, DecisionT]:
        """At a cycle boundary: the last accepted scene becomes the running one (one read, whole)."""
        latest = self._latest
        if latest is not self.running:
            self.running = latest
            self.applied += 1
        return latest

    def replace(self, gate: Gate[SceneT, DecisionT], scene: SceneT, decision: DecisionT,
                origin: str) -> SceneEntry[SceneT, DecisionT]:
        """From the control thread: ``scene``, judged by ``gate``, runs from now on and stays the
        latest; later uploads are judged by ``gate`` (a derate's: the loop as observed)."""
        with self._lock:
            self.gate = gate
            entry = SceneEntry(len(self.history), origin, scene, decision)
            self.history.append(entry)
            self._latest = self.running = entry
            self.applied += 1
            return entry
