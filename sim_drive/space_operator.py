"""A hand in space: one operator force (a vector, one component per axis) on a multi-axis handle.

A Cartesian device's axes are independent plants (``m_i``, ``b_i``; :mod:`sim_drive.handle`);
what couples them in the simulation is the hand, whose force depends on where the handle is in
space.  :class:`SpacePush` pushes with a force of constant magnitude ``force`` (N) towards a
target point: ``w = force (p - x) / |p - x|`` (0 N at the point itself), towards ``targets[j]``
during the j-th ``dwell`` seconds (the last target from then on).  Pushing towards a sphere's
centre is a push along its normal wherever the handle touches it; towards a point inside a box,
the handle slides along the face it meets until the push is normal to it.

Each axis' drive asks for its own component (:meth:`SpaceHand.axis` gives the
:class:`~sim_drive.operator.OperatorModel` of one axis).  The vector is computed once per SYNC,
from every axis' position at the start of the period that SYNC closes, and held over that
period: the first axis to advance its plant for SYNC ``k`` computes it (every axis is at the
period's start then: the master sends SYNC ``k`` only after every axis' TPDO of SYNC ``k - 1``),
the others reuse it, whatever order their threads run in (a lock orders them; periods are
counted per axis, so axes whose SYNC counters differ still share each period's force).  An axis this
process does not simulate is at 0 m for the hand.

The hand pushes only while every axis it simulates has its torque enabled (OPERATION ENABLED in
cyclic synchronous torque mode), as a person would take the handle once the device is on and
let go of it once it is off: otherwise it pushes nothing, and its time -- the ``t`` of
:meth:`SpaceHand.vector`, which picks the target -- counts from the first period of the
current stretch in which they all are.  So a controller's pre-flight cycles and commissioning
SYNCs, which advance the plants' time, never move the handle -- neither the first run's nor
those of a run after it (a hand that kept pushing the unpowered handle after a run had pushed
it through the walls before the next run's safe start: "handle is inside slope at (313, 7.59,
-0.986) mm", refused).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range
from sim_drive.device import SimulatedDrive
from sim_drive.operator import FORCE_LIMIT, POSITION_LIMIT, TIME_LIMIT, OperatorModel

MODELS = ("none", "push")
ROUNDS_KEPT = 4  # periods whose force is kept for an axis that lags (a node that stopped answering)


class SpaceHand:
    """The hand's force vector, shared by the axes' drives (module docstring); the base class pushes nothing."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._drives: tuple[SimulatedDrive | None, ...] = (None,) * size
        self._lock = threading.Lock()
        self._seen: list[int | None] = [None] * size  # each axis' SYNC count at its last call
        self._round = [0] * size  # each axis' periods so far
        self._vectors: dict[int, list[float]] = {}  # the force of each recent period, by round
        self._since: float | None = None  # the time (s) of the first period of this stretch with every axis enabled

    def bind(self, drives: Sequence[SimulatedDrive | None]) -> None:
        """The simulated drive of every axis (None: an axis simulated elsewhere, at 0 m here)."""
        if len(drives) != self.size:
            raise ParameterError("drives", len(drives), f"one per axis ({self.size})", "hand in space")
        self._drives = tuple(drives)

    def bind_places(self, places: Sequence[int], drives: Sequence[SimulatedDrive]) -> None:
        """Each of ``drives`` the simulated drive of the axis at its entry of ``places`` (coordinates);
        the hand's other axes are simulated elsewhere (at 0 m here)."""
        bound: list[SimulatedDrive | None] = [None] * self.size
        for place, drive in zip(places, drives, strict=True):
            bound[place] = drive
        self.bind(bound)

    def axis(self, index: int) -> OperatorModel:
        """The operator model of axis ``index``: this hand's component along it."""
        return AxisShare(index, self)

    def component(self, axis: int, t: float) -> float:
        """Axis ``axis``'s component (N) of the force over the period starting at ``t`` s."""
        drive = self._drives[axis]
        count = drive.sync_count if drive is not None else None
        with self._lock:
            if count is None or count != self._seen[axis]:  # a new period for this axis
                self._seen[axis] = count
                self._round[axis] += 1
            period = self._round[axis]
            vector = self._vectors.get(period)
            if vector is None:  # the first axis into this period: every axis is at its start
                vector = self._vectors[period] = self._held(t)
                for old in [k for k in self._vectors if k < period - ROUNDS_KEPT]:
                    del self._vectors[old]
            return vector[axis]

    def _held(self, t: float) -> list[float]:
        """The force over the period starting at the drives' time ``t`` s: nothing unless every simulated
        axis is enabled, else :meth:`vector` at the time since they all were."""
        drives = [d for d in self._drives if d is not None]
        if not drives or not all(d.torque_enabled for d in drives):
            self._since = None  # let go: the next enabling starts the hand's script again
            return [0.0] * self.size
        if self._since is None:
            self._since = t
        positions = [d.handle.position if d is not None else 0.0 for d in self._drives]
        return self.vector(t - self._since, positions)

    def vector(self, t: float, positions: Sequence[float]) -> list[float]:
        """The force (N per axis) ``t`` s after the hand took the handle, with it at ``positions`` (m)."""
        return [0.0] * self.size

    def energy_balance(self) -> float:
        """The operator's work over every simulated axis (J), from each drive's exact ledger."""
        return math.fsum(d.operator_energy for d in self._drives if d is not None)


class SpacePush(SpaceHand):
    """Pushes with ``force`` N towards ``targets[j]`` (points in m, one coordinate per axis) during the
    j-th ``dwell`` s, the last target from then on (module docstring)."""

    def __init__(self, targets: Sequence[Sequence[float]], force: float, dwell: float = math.inf) -> None:
        points = [tuple(point) for point in targets]
        if not points or len({len(p) for p in points}) != 1:
            raise ParameterError("toward", targets, "one or more points with the same number of coordinates",
                                 "hand in space")
        super().__init__(len(points[0]))
        self.targets = tuple(tuple(real_in_range("toward", c, -POSITION_LIMIT, POSITION_LIMIT, unit="m",
                                                 context="hand in space") for c in p) for p in points)
        self.force = real_in_range("force", force, 0.0, FORCE_LIMIT, unit="N", context="hand in space")
        self.dwell = math.inf if dwell == math.inf else real_in_range("dwell", dwell, 0.0, TIME_LIMIT, unit="s",
                                                                      low_inclusive=False, context="hand in space")

    def target(self, t: float) -> tuple[float, ...]:
        """The point pushed towards at time ``t`` s."""
        index = 0 if self.dwell == math.inf else min(int(t // self.dwell), len(self.targets) - 1)
        return self.targets[index]

    def vector(self, t: float, positions: Sequence[float]) -> list[float]:
        """``force (p - x) / |p - x|`` N (0 at the point itself)."""
        offset = [p - x for p, x in zip(self.target(t), positions)]
        distance = math.hypot(*offset)
        return [0.0] * self.size if distance == 0.0 else [self.force * c / distance for c in offset]


@dataclass(frozen=True)
class AxisShare(OperatorModel):
    """One axis' share of a :class:`SpaceHand`: its component, held over each period."""

    index: int
    hand: SpaceHand

    def force(self, t: float, position: float, velocity: float) -> float:
        """The hand's component along this axis, N."""
        return self.hand.component(self.index, t)

    def parameters(self) -> tuple[float, ...]:
        """The axis index (the hand itself is no number)."""
        return (float(self.index),)


def hand_from_table(table: Mapping[str, Any], size: int) -> SpaceHand:
    """A hand from a profile's ``[space.operator]``: ``model`` ("none" or "push"); for "push"
    ``force`` (N), ``toward`` (a point, or a list of points, m, ``size`` coordinates each) and
    ``dwell`` (s per point; default: one point forever).  ParameterError names the field."""
    params = dict(table)
    model = params.pop("model", "none")
    if model not in MODELS:
        raise ParameterError("space.operator.model", model, " or ".join(map(repr, MODELS)), "profile")
    if model == "none":
        if params:
            raise ParameterError("space.operator", sorted(params), "no other key with model = \"none\"", "profile")
        return SpaceHand(size)
    unknown = sorted(set(params) - {"force", "toward", "dwell"})
    if unknown or "force" not in params or "toward" not in params:
        raise ParameterError("space.operator", sorted(params), "force, toward and optionally dwell", "profile")
    toward = params["toward"]
    points = toward if isinstance(toward, (list, tuple)) and toward and isinstance(toward[0], (list, tuple)) else [toward]
    if any(not isinstance(p, (list, tuple)) or len(p) != size for p in points):
        raise ParameterError("space.operator.toward", toward, f"a point of {size} coordinates (m), or a list of them",
                             "profile")
    return SpacePush(points, params["force"], params.get("dwell", math.inf))
