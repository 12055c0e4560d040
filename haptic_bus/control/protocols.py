"""What the controller asks of a scene and of a gate, at any axis count.

One axis renders a 1-D :class:`~haptic_bus.control.scene.CompiledScene` judged by the
:class:`~haptic_bus.control.gate.PassivityGate`; several coupled axes a
:class:`~haptic_bus.control.space_scene.SpaceScene` judged by the coupled
:class:`~haptic_bus.control.space_gate.SpaceGate`.  Both pairs meet these protocols, and the
controller (:class:`~haptic_bus.control.controller.WallController`) and its scene switch
(:class:`~haptic_bus.control.scene_switch.SceneSwitch`) know nothing else of them.  Units: positions
in m, velocities in m/s, forces in N, stiffness in N/m, damping and margins in N s/m, energy in J.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, Self, TypeVar


class SceneObject(Protocol):
    """One object of a scene: its name and its wall's ``stiffness`` (N/m) and ``damping`` (N s/m)."""

    @property
    def name(self) -> str: ...

    @property
    def stiffness(self) -> float: ...

    @property
    def damping(self) -> float: ...


class Scene(Protocol):
    """A compiled scene: the wall force for the handle's position and velocity, and its objects.

    ``x`` and ``v`` are floats (m, m/s) for a 1-D scene and one coordinate per axis (arrays) for a
    scene in space; ``force`` returns the same shape (N, the analysis' ``u``: the handle feels ``-u``).
    """

    @property
    def objects(self) -> Sequence[SceneObject]: ...

    def force(self, x: Any, v: Any) -> Any:
        """The wall force ``u`` (N) at ``x`` (m) moving at ``v`` (m/s)."""
        ...

    def force_floats(self, x: Sequence[float], v: Sequence[float]) -> list[float]:
        """:meth:`force` with ``x`` (m) and ``v`` (m/s) as floats, one per axis, and ``u`` (N) as a list of
        floats: what the controller asks of a scene every cycle of several axes, with no array made."""
        ...

    def stored_energy(self, x: Any) -> float:
        """The energy (J) the springs acting at ``x`` (m) hold."""
        ...

    def touching(self, x: Any) -> tuple[str, ...]:
        """The names of the objects whose spring acts on the handle at ``x`` (m): penetrated, ``K > 0``."""
        ...

    def by_name(self) -> Mapping[str, SceneObject]:
        """The objects by name."""
        ...

    def with_walls(self, changes: Mapping[str, tuple[float, float]]) -> Self:
        """The same scene with the named objects' ``(K, B)`` (N/m, N s/m) changed, compiled."""
        ...

    def object_dicts(self) -> list[dict[str, Any]]:
        """Every object, JSON-ready (its kind, geometry, ``K`` and ``B``)."""
        ...


class Decision(Protocol):
    """A gate's decision on a scene: accepted or not, why, its least margin (N s/m), every wall judged."""

    @property
    def accepted(self) -> bool: ...

    @property
    def reasons(self) -> tuple[str, ...]: ...

    @property
    def warnings(self) -> tuple[str, ...]: ...

    @property
    def worst_margin(self) -> float | None: ...

    def wall_dicts(self) -> list[dict[str, Any]]:
        """Every wall judged (its objects, ``K``/``B``, margin), JSON-ready."""
        ...


class AxisLoop(Protocol):
    """One axis' loop as a gate assumes it: period ``T`` (s), friction ``b`` (N s/m), loop ``delay`` (samples)."""

    @property
    def T(self) -> float: ...

    @property
    def b(self) -> float: ...

    @property
    def delay(self) -> float: ...


class RampVerdict(Protocol):
    """Whether a start ramp (every wall scaled by ``s`` from 0 to 1) is passive all the way, and why not."""

    @property
    def proven(self) -> bool: ...

    @property
    def reason(self) -> str: ...


SceneT = TypeVar("SceneT", bound=Scene)
DecisionT = TypeVar("DecisionT", bound=Decision)
SceneT_contra = TypeVar("SceneT_contra", bound=Scene, contravariant=True)
DecisionT_co = TypeVar("DecisionT_co", bound=Decision, covariant=True)


class Gate(Protocol[SceneT_contra, DecisionT_co]):
    """A passivity gate: judges scenes for its axes' loops (one axis, or several coupled)."""

    @property
    def axes(self) -> Sequence[AxisLoop]: ...

    def judge(self, scene: SceneT_contra) -> DecisionT_co:
        """The decision on ``scene``, never raising for a refusal."""
        ...

    def admit(self, scene: SceneT_contra) -> DecisionT_co:
        """The decision on ``scene``; :class:`~haptic_bus.errors.Refusal` if refused."""
        ...

    def proves_ramp(self, scene: SceneT_contra) -> RampVerdict:
        """Whether ``scene``'s walls scaled by every ``s`` in [0, 1] are passive (a start ramp's proof)."""
        ...
