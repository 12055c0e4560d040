"""The steady state of a multi-axis demo (``haptic-bus demo --profile gantry-3d``), read against the simulated device.

The simulated device (one CANopen slave per axis and the profile's hand in space,
:class:`sim_drive.canopen.multi_axis.MultiAxisSim`) knows the truth; the hand pushes towards its
targets, and just before the end of each target's dwell (:data:`STEADY_LEAD`) and at the end the
demo (:mod:`~haptic_bus.app.demo`) reads the steady state (:class:`SteadyState`): the force the
controller asks along the contact's normal against ``K`` times the penetration it measures, the
force the drives apply (their torques, whole per mille) against the hand's push, and ``K`` times
the true penetration (the simulated drives' exact positions).  Units SI: m, N, N/m, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.app.profiles import AxesProfile
from haptic_bus.app.rig import MultiAxisSim
from haptic_bus.control.controller import WallController
from haptic_bus.control.space_gate import SpaceDecision
from haptic_bus.control.space_scene import SpaceScene

STEADY_LEAD = 0.05  # s: a steady state is read this long before the hand turns to its next target
STILL_TOUR = 8.0  # s: the demo of a hand that stays on one target (or pushes nothing)


@dataclass(frozen=True)
class SteadyState:
    """One steady state (SI): at ``time_s``, in contact with ``obj`` of stiffness ``stiffness``.

    ``penetration``: the depth at the controller's measured position (0x606C summed, m);
    ``normal_force``: the force the controller asked along the outward normal (N); ``applied``:
    the drives' applied force along it (their torques x the per-mille unit, N) and ``torques``
    (per mille); ``push``: the hand's force into the object along it (N); ``true_penetration``:
    the depth at the simulated drives' exact positions (m); ``quantum``: the largest force
    rounding the per-mille torques allow along the normal (N, ``sqrt(sum (n_i u_i / 2)^2)``,
    ``u_i`` an axis' newton per per mille)."""

    time_s: float
    obj: str
    stiffness: float
    penetration: float
    normal_force: float
    applied: float
    torques: tuple[int, ...]
    push: float
    true_penetration: float
    quantum: float

    @property
    def relative_error(self) -> float:
        """``|normal_force - K penetration| / (K penetration)``: the controller's own chain."""
        expected = self.stiffness * self.penetration
        return abs(self.normal_force - expected) / expected


def contact(scene: SpaceScene, x: np.ndarray) -> tuple[str, float, float, np.ndarray] | None:
    """The one object penetrated at ``x`` (m): its name, stiffness (N/m), depth (m) and outward
    normal; None for none (or for several at once, which a single steady state does not name)."""
    hits = [(obj, obj.penetration(x.tolist())) for obj in scene.objects]
    found = [(obj, hit) for obj, hit in hits if hit is not None]
    if len(found) != 1:
        return None
    obj, (depth, normal) = found[0]
    return obj.name, obj.stiffness, depth, np.array(normal)


def steady_state(controller: WallController[SpaceScene, SpaceDecision], sim: MultiAxisSim) -> SteadyState | None:
    """The steady state of the latest cycle (:class:`SteadyState`), None out of contact."""
    rows = [record.latest() for record in controller.records]
    if any(row is None for row in rows):
        return None
    q = np.array([row["position_m"] for row in rows if row is not None])
    x = controller.kinematics.position(q)
    touching = contact(controller.scene, x)
    if touching is None:
        return None
    name, stiffness, depth, normal = touching
    wall = np.array([row["force_n"] for row in rows if row is not None])
    units = np.array([s.newton_per_permille for s in controller.axes.scalings])
    torques = tuple(int(node.drive.torque_actual) for node in sim.nodes)
    applied = float(np.dot(np.array(torques) * units, normal))  # the motor force on the handle, outward
    push = -float(np.dot(sim.hand.vector(sim.nodes[0].drive.time, sim.positions), normal))
    true = contact(controller.scene, controller.kinematics.position(np.array(sim.positions)))
    return SteadyState(controller.now(), name, stiffness, depth, -float(np.dot(wall, normal)), applied, torques, push,
                       true[2] if true is not None else 0.0, float(np.linalg.norm(normal * units / 2.0)))


def tour_seconds(profile: AxesProfile) -> float:
    """How long (s) the profile's hand takes to visit every target (``dwell`` each), once it has taken
    the handle; :data:`STILL_TOUR` where it has a single target or none."""
    dwell = profile.operator_model.get("dwell", math.inf)
    targets = len(profile.operator_model.get("toward", ()))
    return dwell * targets if math.isfinite(dwell) and targets > 1 else STILL_TOUR


def dwell_ends(profile: AxesProfile, seconds: float, cycles: int) -> set[int]:
    """The cycles at which a demo of ``seconds`` (``cycles`` cycles) reads a steady state: just
    before the end of each target's dwell (:data:`STEADY_LEAD`), and its last."""
    period = profile.period
    dwell = profile.operator_model.get("dwell", math.inf)
    lead = round(STEADY_LEAD / period)
    ends = {round(j * dwell / period) - lead for j in range(1, len(profile.operator_model.get("toward", ())) + 1)
            if j * dwell < seconds} if math.isfinite(dwell) else set()
    ends.add(cycles - 1)
    return ends
