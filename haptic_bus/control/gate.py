"""The passivity gate: every change of wall parameters passes here first, whatever its path.

The gate judges the loop *as configured* -- device mass ``m`` (kg), effective friction ``b``
(N s/m), period ``T`` (s), loop delay ``d`` (samples, from the drive's timing) -- with the
exact criterion of :mod:`haptic_bus.analysis.criterion`, for every summed ``(K, B)`` that can act on
the handle at once (overlapping objects add).  A scene passes when every such wall has
``margin >= safety_margin`` (N s/m).  The seed's bandwidth rule ``alpha = B/(K T) > 6`` is a
warning by default and a refusal under ``bandwidth = "strict"``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

from drives.errors import HapticBusError, ParameterError
from haptic_bus.analysis.criterion import Verdict, exact_verdict
from haptic_bus.analysis.limits import max_damping, max_stiffness
from haptic_bus.analysis.loop import BANDWIDTH_ALPHA, WallLoop
from haptic_bus.control.scene import CompiledScene
from haptic_bus.validation import real_in_range

BANDWIDTH_POLICIES = ("warn", "strict")


@dataclass(frozen=True)
class GatePolicy:
    """``safety_margin`` in N s/m (>= 0) and the bandwidth rule's policy ("warn" or "strict")."""

    safety_margin: float = 0.0
    bandwidth: str = "warn"

    def __post_init__(self) -> None:
        object.__setattr__(self, "safety_margin",
                           real_in_range("safety_margin", self.safety_margin, 0.0, 1e12, unit="N s/m", context="gate"))
        if self.bandwidth not in BANDWIDTH_POLICIES:
            raise ParameterError("bandwidth", self.bandwidth, " or ".join(BANDWIDTH_POLICIES), "gate")


@dataclass(frozen=True)
class DeviceLoop:
    """The loop the walls run in: ``m`` kg, effective ``b`` N s/m, ``T`` s, ``delay`` samples."""

    m: float
    b: float
    T: float
    delay: int

    def wall(self, K: float, B: float) -> WallLoop:
        return WallLoop(self.m, self.b, self.T, K, B, self.delay)


@dataclass(frozen=True)
class WallJudgement:
    """The gate's view of one ``(K, B)`` that can act at once, and the objects that make it."""

    objects: tuple[str, ...]
    K: float
    B: float
    verdict: Verdict
    alpha: float


@dataclass(frozen=True)
class GateDecision:
    """Whether a scene passes, the judgement of every contact wall, and warnings."""

    accepted: bool
    walls: tuple[WallJudgement, ...]
    reasons: tuple[str, ...] = ()
    warnings: tuple[str, ...] = field(default_factory=tuple)

    @property
    def worst_margin(self) -> float | None:
        """The smallest margin over the contact walls (N s/m), None for an empty scene."""
        return min((w.verdict.margin for w in self.walls), default=None)


class GateRefusal(HapticBusError):
    """A change of wall parameters was refused; ``decision`` holds every reason."""

    def __init__(self, decision: GateDecision) -> None:
        self.decision = decision
        super().__init__("passivity gate refused the change: " + "; ".join(decision.reasons))


@functools.lru_cache(maxsize=4096)
def _judge_wall(loop: WallLoop) -> Verdict:
    return exact_verdict(loop)


class PassivityGate:
    """Judges compiled scenes for one configured loop; thread-safe (it keeps no mutable state
    beyond a verdict cache)."""

    def __init__(self, device: DeviceLoop, policy: GatePolicy = GatePolicy()) -> None:
        self.device = device
        self.policy = policy
        device.wall(0.0, 0.0)  # validates m, b, T, delay now, not at the first upload

    def judge(self, scene: CompiledScene) -> GateDecision:
        """The decision on ``scene``, never raising for a refusal."""
        walls, reasons, warnings = [], [], []
        for (K, B), names in sorted(scene.contacts().items()):
            loop = self.device.wall(K, B)
            verdict = _judge_wall(loop)
            walls.append(WallJudgement(names, K, B, verdict, loop.alpha))
            label = f"{'+'.join(names)} (K = {K:g} N/m, B = {B:g} N s/m)"
            if verdict.margin < self.policy.safety_margin:
                reasons.append(self._explain(label, loop, verdict))
            if K > 0 and not loop.alpha > BANDWIDTH_ALPHA:
                rule = f"{label}: alpha = B/(K T) = {loop.alpha:.3g}, the bandwidth rule wants > {BANDWIDTH_ALPHA:g}"
                (reasons if self.policy.bandwidth == "strict" else warnings).append(rule)
        return GateDecision(not reasons, tuple(walls), tuple(reasons), tuple(warnings))

    def passes(self, scene: CompiledScene) -> bool:
        """Whether :meth:`judge` would accept ``scene``, without the explanations of a refusal
        (cheap enough for a search over scaled scenes)."""
        strict = self.policy.bandwidth == "strict"
        for K, B in scene.contacts():
            loop = self.device.wall(K, B)
            if _judge_wall(loop).margin < self.policy.safety_margin or (strict and K > 0 and not loop.alpha > BANDWIDTH_ALPHA):
                return False
        return True

    def admit(self, scene: CompiledScene) -> GateDecision:
        """The decision on ``scene``; raises :class:`GateRefusal` if it is refused."""
        decision = self.judge(scene)
        if not decision.accepted:
            raise GateRefusal(decision)
        return decision

    def _explain(self, label: str, loop: WallLoop, verdict: Verdict) -> str:
        d = self.device
        k_max, b_max = max_stiffness(loop), max_damping(loop)
        limits = (f"largest passive K at this B: {'none' if k_max is None else f'{k_max:.6g} N/m'}, "
                  f"largest passive B at this K: {'none' if b_max is None else f'{b_max:.6g} N s/m'}")
        state = "passive" if verdict.passive else ("not passive" if verdict.stable else "unstable")
        return (f"{label} is {state} with m = {d.m:g} kg, b = {d.b:g} N s/m, T = {d.T:g} s, delay = {d.delay}: "
                f"margin {verdict.margin:.4g} N s/m at theta = {verdict.critical_theta:.3g} rad, allowed: margin >= "
                f"{self.policy.safety_margin:g} N s/m; {limits}")
