"""The passivity gate: every change of wall parameters passes here first, whatever its path.

The gate judges the loop *as configured* -- device mass ``m`` (kg), effective friction ``b``
(N s/m), period ``T`` (s), loop delay ``D`` (samples, real: from the drive's timing, or
measured), the velocity the drive reports (:mod:`haptic_bus.analysis.velocity`) -- with the
exact criterion of :mod:`haptic_bus.analysis.criterion`, for every summed ``(K, B)`` that can act on
the handle at once (overlapping objects add); on a device with a transmission
(``DeviceLoop.transmission``) with the two-mass criterion of
:mod:`haptic_bus.analysis.two_mass_criterion` instead.  A scene passes when every such wall has
``margin >= safety_margin`` (N s/m) and, when the device states its encoder resolution and
Coulomb friction (``DeviceLoop.quantisation``), meets the quantisation condition
(:mod:`haptic_bus.analysis.quantisation`).  The gate calls that verdict alone (stability and
``Re T_fund``): an upload or a profile load pays for no passive interval and no out-of-band
exposure; only a refusal's message names the passive intervals.  The seed's bandwidth rule ``alpha = B/(K T) > 6`` is a
warning by default and a refusal under ``bandwidth = "strict"``.  A start ramp (the scene's
walls scaled from 0 to 1) is proven passive on the whole way by :meth:`PassivityGate.proves_ramp`.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from typing import Any

from haptic_bus.analysis.criterion import Verdict, exact_verdict
from haptic_bus.analysis.limits import PassiveSet, passive_limits, passive_scales
from haptic_bus.analysis.loop import BANDWIDTH_ALPHA, DeviceLoop, WallLoop
from haptic_bus.analysis.quantisation import QuantisationCondition, quantisation_condition
from haptic_bus.analysis.two_mass import TwoMassLoop
from haptic_bus.analysis.two_mass_criterion import (
    largest_passive_stiffness,
    two_mass_passive_scales,
    two_mass_verdict,
)
from haptic_bus.control.scene import CompiledScene
from haptic_bus.errors import NAMES_SHOWN, ParameterError, Refusal
from haptic_bus.validation import real_in_range, some_names

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
class RampProof:
    """Whether a start ramp of a scene (every wall scaled by ``s`` from 0 to 1) is passive all the
    way: ``proven``, and for each contact wall its passive scales (``s`` in [0, 1])."""

    proven: bool
    walls: tuple[tuple[tuple[str, ...], PassiveSet], ...]

    @property
    def reason(self) -> str:
        """Why the ramp is not proven ('' when it is): the first wall whose scales leave a gap."""
        for names, scales in self.walls:
            if not whole_ramp(scales):
                return f"{some_names(names)} scaled by s is passive only for s in {scales.describe('', 4)}, not all of [0, 1]"
        return ""


def whole_ramp(scales: PassiveSet) -> bool:
    """The scales are the one closed interval [0, 1]."""
    return scales.intervals[:1] == ((0.0, 1.0),) and scales.ends()[0] == (True, True)


@dataclass(frozen=True)
class WallJudgement:
    """The gate's view of one ``(K, B)`` that can act at once, and the objects that make it
    (``quantisation``: its quantisation condition, None when the device states none)."""

    objects: tuple[str, ...]
    K: float
    B: float
    verdict: Verdict
    alpha: float
    quantisation: QuantisationCondition | None = None


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

    def wall_dicts(self) -> list[dict[str, Any]]:
        """Every contact wall judged: its objects, ``K`` (N/m), ``B`` (N s/m), margin (N s/m), critical ``theta``
        (rad) and, when the device states one, its quantisation condition."""
        return [{"objects": list(w.objects), "K": w.K, "B": w.B, "margin": w.verdict.margin,
                 "critical_theta": w.verdict.critical_theta,
                 **({} if w.quantisation is None else {"quantisation": w.quantisation.to_dict()})} for w in self.walls]


@functools.lru_cache(maxsize=4096)
def _judge_wall(loop: WallLoop) -> Verdict:
    return exact_verdict(loop)


@functools.lru_cache(maxsize=4096)
def _judge_two_mass(loop: TwoMassLoop) -> Verdict:
    return two_mass_verdict(loop)


class PassivityGate:
    """Judges compiled scenes for one configured loop; thread-safe (it keeps no mutable state
    beyond a verdict cache)."""

    def __init__(self, device: DeviceLoop, policy: GatePolicy = GatePolicy()) -> None:
        self.device = device
        self.policy = policy
        device.wall(0.0, 0.0)  # validates m, b, T, delay now, not at the first upload

    @property
    def axes(self) -> tuple[DeviceLoop]:
        """The one axis' loop (the gate protocol's :attr:`~haptic_bus.control.protocols.Gate.axes`)."""
        return (self.device,)

    def judge(self, scene: CompiledScene) -> GateDecision:
        """The decision on ``scene``, never raising for a refusal."""
        walls: list[WallJudgement] = []
        reasons: list[str] = []
        warnings: list[str] = []
        explained = 0  # refusals by margin given their passive intervals: the first few
        for (K, B), names in sorted(scene.contacts().items()):
            loop = self.device.wall(K, B)
            verdict = self._verdict(loop)
            quantised = self._quantised(loop)
            walls.append(WallJudgement(names, K, B, verdict, loop.alpha, quantised))
            label = f"{some_names(names)} (K = {K:g} N/m, B = {B:g} N s/m)"
            if verdict.margin < self.policy.safety_margin:  # the passive intervals for the first few only
                reasons.append(self._explain(label, loop, verdict, limits=explained < NAMES_SHOWN))
                explained += 1
            if quantised is not None and not quantised.holds:
                reasons.append(f"{label} is not passive with {self.device.describe()}: {quantised.describe()}")
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
            if self._verdict(loop).margin < self.policy.safety_margin or (strict and K > 0 and not loop.alpha > BANDWIDTH_ALPHA):
                return False
            quantised = self._quantised(loop)
            if quantised is not None and not quantised.holds:
                return False
        return True

    def _quantised(self, loop: WallLoop) -> QuantisationCondition | None:
        """The quantisation condition of ``loop``'s wall, None when the device states no quantisation."""
        quantisation = self.device.quantisation
        return None if quantisation is None else quantisation_condition(loop, quantisation)

    def proves_ramp(self, scene: CompiledScene) -> RampProof:
        """Whether every contact wall of ``scene``, scaled by every ``s`` in [0, 1], is passive:
        the proof a start ramp needs (the end point alone is not enough: with a delay, part
        of the way can be active).  Exact over the continuum of ``s``
        (:func:`~haptic_bus.analysis.limits.passive_scales`; on a two-mass device a sampled search,
        :func:`~haptic_bus.analysis.two_mass_criterion.two_mass_passive_scales`), margin >= 0; the end point meets
        the policy's safety margin through :meth:`admit`."""
        walls = tuple((names, self._scales(self.device.wall(K, B)))
                      for (K, B), names in sorted(scene.contacts().items()))
        proven = all(whole_ramp(scales) for _, scales in walls)
        return RampProof(proven, walls)

    def later(self, extra: float) -> PassivityGate:
        """This gate for a loop ``extra`` samples later (a derate's gate)."""
        return PassivityGate(dataclasses.replace(self.device, delay=self.device.delay + extra), self.policy)

    def passive_scales(self, scene: CompiledScene) -> tuple[tuple[float, float], ...]:
        """The scales ``s`` in [0, 1] at which every contact wall of ``scene``, scaled to
        ``(s K, s B)``, is passive (margin >= 0): disjoint closed intervals, ascending."""
        common: list[tuple[float, float]] = [(0.0, 1.0)]
        for K, B in scene.contacts():
            intervals = self._scales(self.device.wall(K, B)).intervals
            common = [(max(lo, a), min(hi, b)) for lo, hi in common for a, b in intervals if max(lo, a) <= min(hi, b)]
        return tuple(common)

    def admit(self, scene: CompiledScene) -> GateDecision:
        """The decision on ``scene``; raises :class:`Refusal` if it is refused."""
        decision = self.judge(scene)
        if not decision.accepted:
            raise Refusal.by_gate(decision)
        return decision

    def _verdict(self, loop: WallLoop) -> Verdict:
        """The exact verdict on ``loop``: the two-mass criterion when the device states a transmission."""
        transmission = self.device.transmission
        return _judge_wall(loop) if transmission is None else _judge_two_mass(TwoMassLoop(loop, transmission))

    def _scales(self, loop: WallLoop) -> PassiveSet:
        """The passive scales of ``loop``'s wall: exact (rigid), sampled (two-mass: :func:`two_mass_passive_scales`)."""
        transmission = self.device.transmission
        return passive_scales(loop) if transmission is None else two_mass_passive_scales(TwoMassLoop(loop, transmission))

    def _with_margin(self, loop: WallLoop) -> str:
        """What passes with the policy's safety margin on a rigid device: the passive K and B of the loop
        with ``b`` lowered by the margin (``Re Z = b + wall terms``, so a margin ``>= s`` at ``b`` is
        passivity at ``b - s``); nothing when there is no margin, or it exceeds ``b``."""
        margin = self.policy.safety_margin
        if margin <= 0.0 or margin > loop.b:
            return ""
        stiffness, damping = passive_limits(dataclasses.replace(loop, b=loop.b - margin))
        return (f"; with margin >= {margin:g} N s/m: K at this B {stiffness.describe('N/m', 6)}, "
                f"B at this K {damping.describe('N s/m', 6)}")

    def _explain(self, label: str, loop: WallLoop, verdict: Verdict, limits: bool = True) -> str:
        """A refusal's reason; only a refusal pays for the passive intervals it names, and only for the first
        :data:`~haptic_bus.errors.NAMES_SHOWN` walls it refuses (``limits`` False: the margin alone; a
        refusal's message shows that many, and 3 000 overlapping walls spent 20 s of a profile check on them)."""
        transmission = self.device.transmission
        if not limits:
            limits_said = ""
        elif transmission is None:
            stiffness, damping = passive_limits(loop)
            limits_said = (f"; passive K at this B: {stiffness.describe('N/m', 6)}; "
                           f"passive B at this K: {damping.describe('N s/m', 6)}") + self._with_margin(loop)
        else:
            largest = largest_passive_stiffness(TwoMassLoop(loop, transmission))
            limits_said = ("; two-mass criterion; passive K at this B from 0: "
                           + ("none" if largest is None else f"up to {largest:.6g} N/m"))
        state = {"lossless oscillator": "a lossless oscillator (poles on the unit circle)",
                 "marginal": "marginal (a pole on the unit circle)"}.get(verdict.outcome, verdict.outcome)
        return (f"{label} is {state} with {self.device.describe()}: margin {verdict.margin:.4g} N s/m at "
                f"theta = {verdict.critical_theta:.3g} rad, allowed: margin >= {self.policy.safety_margin:g} N s/m"
                f"{limits_said}")
