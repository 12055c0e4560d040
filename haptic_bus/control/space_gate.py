"""The passivity gate for a scene in space on coupled axes (issue 22): every wall a contact can make.

The device: a Cartesian set of axes (:mod:`haptic_bus.control.kinematics`), each a
:class:`~haptic_bus.analysis.loop.WallLoop` with its own ``m``, ``b``, velocity model and delay.
A contact with an object is, linearised, a plane wall ``K n n^T``, ``B n n^T`` along the
object's penetration normal ``n``, judged by the exact coupled criterion
(:func:`~haptic_bus.analysis.coupled.coupled_verdict`); the gate asks every such wall for
``margin >= safety_margin`` (N s/m, :class:`~haptic_bus.control.gate.GatePolicy`).

* a plane: its normal;
* a box: its face normals (one per axis: ``n`` and ``-n`` are one wall);
* a sphere: every direction can be its normal.  Judged on the directions :func:`sphere_directions`
  gives (the axes, the diagonals of every pair of axes, the diagonals of the cube) and then from
  the worst of them a local search of the least margin (Nelder-Mead over the direction, at most
  ``SEARCH_EVALUATIONS`` verdicts): a search, not a proof over the continuum of directions.
* two objects whose solids meet (bounding boxes overlap; a plane's half-space meets the other's
  box) add: ``K1 n1 n1^T + K2 n2 n2^T`` for every pair of their directions (a sphere's sampled
  ones).  Three or more objects overlapping at one point are not judged together.

Verdicts are cached per wall (the same ``K``, ``B`` and normals on the same axes are judged once in a
process), and a pickled gate carries those on its axes: the judge worker it is handed to does not judge
them again.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from haptic_bus.analysis.coupled import CoupledVerdict, coupled_verdict
from haptic_bus.analysis.coupled_limits import passive_along
from haptic_bus.analysis.coupled_loop import CoupledLoop, unit_normal
from haptic_bus.analysis.limits import PassiveSet
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.control.gate import GatePolicy, whole_ramp
from haptic_bus.control.space_scene import Box, Plane, SpaceObject, SpaceScene, Sphere
from haptic_bus.errors import Refusal
from haptic_bus.validation import some_names

SEARCH_EVALUATIONS = 24
DEFAULT_POLICY = GatePolicy()
Parts = tuple[tuple[float, float, tuple[float, ...]], ...]
"""Plane walls summed: ``((K N/m, B N s/m, unit normal), ...)``."""
VerdictKey = tuple[tuple[WallLoop, ...], Parts]
CACHE_SIZE = 4096  # verdicts kept per process, the least recently used dropped first
_verdicts: OrderedDict[VerdictKey, CoupledVerdict] = OrderedDict()
_verdicts_lock = threading.Lock()


def sphere_directions(size: int) -> list[tuple[float, ...]]:
    """Unit directions up to sign: the axes, ``(e_i +- e_j)/sqrt 2`` and ``(1, +-1, .., +-1)/sqrt size``."""
    eye = np.eye(size)
    found = [eye[i] for i in range(size)]
    found += [(eye[i] + s * eye[j]) / math.sqrt(2) for i, j in itertools.combinations(range(size), 2) for s in (1, -1)]
    if size > 2:
        found += [np.array((1.0, *signs)) / math.sqrt(size) for signs in itertools.product((1.0, -1.0), repeat=size - 1)]
    return [tuple(float(c) for c in d) for d in found]


def object_directions(obj: SpaceObject, size: int) -> list[tuple[float, ...]]:
    """The normals a contact with ``obj`` can have (up to sign; a sphere's sampled)."""
    if isinstance(obj, Plane):
        return [obj.normal]
    if isinstance(obj, Box):
        return obj.face_normals()
    return sphere_directions(size)


def _overlap(a: SpaceObject, b: SpaceObject) -> bool:
    """Whether the solids of ``a`` and ``b`` can meet (bounding boxes; a plane against the other's box)."""
    if isinstance(a, Plane) and isinstance(b, Plane):  # two half-spaces are disjoint only back to back, apart
        facing = float(np.dot(a.normal, b.normal))
        return facing > -1.0 + 1e-12 or float(np.dot(b.point, a.normal)) < float(np.dot(a.point, a.normal))
    if isinstance(a, Plane) or isinstance(b, Plane):
        plane, other = (a, b) if isinstance(a, Plane) else (b, a)
        assert isinstance(plane, Plane) and not isinstance(other, Plane)
        low, high = other.bounds()
        return bool(plane.meets(low[None, :], high[None, :])[0])
    assert not isinstance(a, Plane) and not isinstance(b, Plane)
    (alow, ahigh), (blow, bhigh) = a.bounds(), b.bounds()
    return bool(np.all(alow < bhigh) and np.all(blow < ahigh))


@dataclass(frozen=True)
class SpaceWall:
    """One wall a contact can make: the objects, each one's ``(K, B, normal)``, and its verdict."""

    objects: tuple[str, ...]
    parts: tuple[tuple[float, float, tuple[float, ...]], ...]
    verdict: CoupledVerdict


@dataclass(frozen=True)
class SpaceDecision:
    """Whether a scene in space passes, every wall judged (the worst per object or pair), and the reasons."""

    accepted: bool
    walls: tuple[SpaceWall, ...]
    reasons: tuple[str, ...] = field(default_factory=tuple)
    warnings: tuple[str, ...] = field(default_factory=tuple)

    @property
    def worst_margin(self) -> float | None:
        """The least margin over the walls (N s/m), None for an empty scene."""
        return min((w.verdict.margin for w in self.walls), default=None)

    def wall_dicts(self) -> list[dict[str, Any]]:
        """Every wall judged: its objects, margin (N s/m), outcome, and each part's ``K`` (N/m), ``B`` (N s/m), normal."""
        return [{"objects": list(w.objects), "margin": w.verdict.margin, "outcome": w.verdict.outcome,
                 "parts": [{"K": K, "B": B, "normal": list(n)} for K, B, n in w.parts]} for w in self.walls]


@dataclass(frozen=True)
class SpaceRampProof:
    """Whether a start ramp of a scene in space (every wall scaled by ``s`` from 0 to 1, along each
    contact normal) is passive all the way: ``proven``, and per object and normal its passive scales."""

    proven: bool
    walls: tuple[tuple[str, tuple[float, ...], PassiveSet], ...]
    overlapping: tuple[tuple[str, str], ...] = ()

    @property
    def reason(self) -> str:
        """Why the ramp is not proven ('' when it is): the first wall whose scales leave a gap, or overlapping objects."""
        for name, normal, scales in self.walls:
            if not whole_ramp(scales):
                return (f"{name} scaled by s along ({', '.join(f'{c:.3g}' for c in normal)}) is passive only for "
                        f"s in {scales.describe('', 4)}, not all of [0, 1]")
        if self.overlapping:
            a, b = self.overlapping[0]
            return f"{a} and {b} overlap: the ramp of two objects acting together is not judged"
        return ""


class SpaceGate:
    """Judges scenes in space on one set of coupled axes (module docstring); thread-safe (a verdict cache only)."""

    def __init__(self, axes: tuple[WallLoop, ...], policy: GatePolicy = DEFAULT_POLICY) -> None:
        self.axes = tuple(axes)
        self.policy = policy
        CoupledLoop(self.axes, np.zeros((len(self.axes),) * 2), np.zeros((len(self.axes),) * 2))  # validates the axes now

    def __getstate__(self) -> dict[str, Any]:
        """The gate with the verdicts this process holds on its axes: a gate unpickled in another
        process (the judge worker) does not judge them again."""
        return {"axes": self.axes, "policy": self.policy, "verdicts": _known(self.axes)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.axes, self.policy = state["axes"], state["policy"]
        _remember(state["verdicts"])

    def wall(self, parts: Parts) -> CoupledVerdict:
        """The verdict on the sum of the plane walls ``parts`` = ``((K, B, normal), ...)``; cached."""
        return _judge(self.axes, tuple((K, B, tuple(unit_normal(n, len(self.axes)))) for K, B, n in parts))

    def _sphere(self, name: str, K: float, B: float) -> SpaceWall:
        size = len(self.axes)

        def margin(direction: np.ndarray) -> float:
            return self.wall(((K, B, tuple(direction)),)).margin if np.any(direction) else math.inf

        start = np.array(min(sphere_directions(size), key=lambda d: margin(np.array(d))))
        best = start
        if size > 1:
            from scipy.optimize import minimize  # lazily: only spheres need the search

            found = minimize(margin, start, method="Nelder-Mead", options={"maxfev": SEARCH_EVALUATIONS, "xatol": 1e-3})
            if margin(found.x) < margin(start):
                best = found.x
        direction = tuple(float(c) for c in unit_normal(best, size))
        return SpaceWall((name,), ((K, B, direction),), self.wall(((K, B, direction),)))

    def judge(self, scene: SpaceScene) -> SpaceDecision:
        """The decision on ``scene``, never raising for a refusal."""
        if scene.objects and scene.dimension != len(self.axes):
            return SpaceDecision(False, (), (f"the scene has {scene.dimension} coordinates, the device {len(self.axes)} axes",))
        walls: list[SpaceWall] = []
        for obj in scene.objects:
            if isinstance(obj, Sphere):
                walls.append(self._sphere(obj.name, obj.stiffness, obj.damping))
                continue
            judged = [SpaceWall((obj.name,), ((obj.stiffness, obj.damping, n),), self.wall(((obj.stiffness, obj.damping, n),)))
                      for n in object_directions(obj, len(self.axes))]
            walls.append(min(judged, key=lambda w: w.verdict.margin))
        for a, b in itertools.combinations(scene.objects, 2):
            if not _overlap(a, b):
                continue
            judged = [SpaceWall((a.name, b.name), parts, self.wall(parts))
                      for na in object_directions(a, len(self.axes)) for nb in object_directions(b, len(self.axes))
                      for parts in [((a.stiffness, a.damping, na), (b.stiffness, b.damping, nb))]]
            walls.append(min(judged, key=lambda w: w.verdict.margin))
        reasons = [self._explain(w) for w in walls if w.verdict.margin < self.policy.safety_margin]
        return SpaceDecision(not reasons, tuple(walls), tuple(reasons))

    def proves_ramp(self, scene: SpaceScene) -> SpaceRampProof:
        """Whether every object's wall, scaled by every ``s`` in [0, 1], is passive along each normal a
        contact with it can have (a sphere's: the sampled ones and the least-margin one the search
        finds, as :meth:`judge` has them): exact over the continuum of ``s``
        (:func:`~haptic_bus.analysis.coupled_limits.passive_along`), margin >= 0.  Two overlapping
        objects are not judged together: the ramp is then not proven."""
        size = len(self.axes)

        def normals(obj: SpaceObject) -> list[tuple[float, ...]]:
            sampled = object_directions(obj, size)
            return [*sampled, self._sphere(obj.name, obj.stiffness, obj.damping).parts[0][2]] if isinstance(obj, Sphere) \
                else sampled

        walls = tuple((obj.name, n, passive_along(self.axes, n, obj.stiffness, obj.damping, "scale"))
                      for obj in scene.objects for n in normals(obj))
        overlapping = tuple((a.name, b.name) for a, b in itertools.combinations(scene.objects, 2) if _overlap(a, b))
        return SpaceRampProof(all(whole_ramp(scales) for _, _, scales in walls) and not overlapping, walls, overlapping)

    def admit(self, scene: SpaceScene) -> SpaceDecision:
        """The decision on ``scene``; raises :class:`Refusal` if it is refused."""
        decision = self.judge(scene)
        if not decision.accepted:
            raise Refusal.by_gate(decision, subject="scene")
        return decision

    def passes(self, scene: SpaceScene) -> bool:
        """Whether :meth:`judge` accepts ``scene``."""
        return self.judge(scene).accepted

    def later(self, extra: float) -> SpaceGate:
        """This gate for loops ``extra`` samples later on every axis (a derate's gate)."""
        return SpaceGate(tuple(dataclasses.replace(loop, delay=loop.delay + extra) for loop in self.axes), self.policy)

    def passive_scales(self, scene: SpaceScene) -> tuple[tuple[float, float], ...]:
        """The scales ``s`` in [0, 1] at which every object of ``scene``, scaled to ``(s K, s B)``, is
        passive (margin >= 0) along each normal :meth:`proves_ramp` judges it on: disjoint closed
        intervals, ascending (objects acting together where they overlap are not judged here:
        :meth:`judge` is)."""
        common: list[tuple[float, float]] = [(0.0, 1.0)]
        for _, _, scales in self.proves_ramp(scene).walls:
            common = [(max(lo, a), min(hi, b)) for lo, hi in common for a, b in scales.intervals
                      if max(lo, a) <= min(hi, b)]
        return tuple(common)

    def _explain(self, wall: SpaceWall) -> str:
        parts = " + ".join(f"K = {K:g} N/m, B = {B:g} N s/m along ({', '.join(f'{c:.3g}' for c in n)})"
                           for K, B, n in wall.parts)
        v = wall.verdict
        return (f"{some_names(wall.objects)} ({parts}) is {v.outcome}: margin {v.margin:.4g} N s/m at theta = "
                f"{v.critical_theta:.3g} rad, allowed: margin >= {self.policy.safety_margin:g} N s/m"
                + self._limits(wall))

    def _limits(self, wall: SpaceWall) -> str:
        """A one-object refusal's passive ``K`` at its ``B`` and ``B`` at its ``K`` along its normal (as the
        1-D gate's refusal names them); a pair's walls are judged together, with no such line."""
        if len(wall.parts) != 1:
            return ""
        K, B, n = wall.parts[0]
        stiffness = passive_along(self.axes, n, K, B, "K").describe("N/m", 6)
        damping = passive_along(self.axes, n, K, B, "B").describe("N s/m", 6)
        return f"; along that normal, passive K at this B: {stiffness}; passive B at this K: {damping}"


def _judge(axes: tuple[WallLoop, ...], parts: Parts) -> CoupledVerdict:
    """The coupled verdict on the walls ``parts`` summed on ``axes``, judged once per process (or
    brought in by an unpickled gate, :func:`_remember`)."""
    key = (axes, parts)
    with _verdicts_lock:
        found = _verdicts.get(key)
        if found is not None:
            _verdicts.move_to_end(key)
            return found
    size = len(axes)
    K, B = np.zeros((size, size)), np.zeros((size, size))
    for k, b, n in parts:
        outer = np.outer(n, n)
        K += k * outer
        B += b * outer
    verdict = coupled_verdict(CoupledLoop(axes, K, B))
    _remember({key: verdict})
    return verdict


def _remember(verdicts: dict[VerdictKey, CoupledVerdict]) -> None:
    """Keep ``verdicts`` in this process's cache (at most :data:`CACHE_SIZE`)."""
    with _verdicts_lock:
        _verdicts.update(verdicts)
        while len(_verdicts) > CACHE_SIZE:
            _verdicts.popitem(last=False)


def _known(axes: tuple[WallLoop, ...]) -> dict[VerdictKey, CoupledVerdict]:
    """The verdicts this process holds on ``axes``."""
    with _verdicts_lock:
        return {key: verdict for key, verdict in _verdicts.items() if key[0] == axes}
