"""One wall loop on a two-mass device judged: what ``haptic-bus check --transmission`` reports.

:func:`check_two_mass` returns a frozen :class:`TwoMassReport`: the exact two-mass verdict
(:mod:`haptic_bus.analysis.two_mass_criterion`, the model named in it), the largest passive ``K``
at this ``B`` on the two-mass device, and beside them the rigid criterion on the device as if it
had no transmission (the handle alone, ``m``) and on its rigid limit (``m + m_motor``), so that
what the transmission costs is read off in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from haptic_bus.analysis.check import MARGIN_UNITS
from haptic_bus.analysis.criterion import Verdict, exact_verdict
from haptic_bus.analysis.loop import WORDS, WallLoop
from haptic_bus.analysis.transmission import Transmission
from haptic_bus.analysis.two_mass import TwoMassLoop
from haptic_bus.analysis.two_mass_criterion import largest_passive_stiffness, two_mass_verdict
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.errors import ParameterError

MODEL = "two-mass: handle (m, b, operator) -- spring and damper -- motor (sensing, wall torque)"
LIMIT_RELATIVE = 1e-6


@dataclass(frozen=True)
class TwoMassReport:
    """A two-mass wall loop's verdict (``verdict``: margin N s/m, critical theta rad), the largest passive
    ``K`` N/m at its ``B`` (None: not even ``K = 0``), and the rigid criterion's verdicts on the handle
    alone (``handle_alone``) and on the rigid limit ``m + m_motor`` (``rigid_limit``)."""

    loop: TwoMassLoop
    verdict: Verdict
    max_stiffness: float | None
    handle_alone: Verdict
    rigid_limit: Verdict

    @property
    def passive(self) -> bool:
        """The two-mass verdict."""
        return self.verdict.passive

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: the two-mass verdict first (``model``, ``criterion``), the rigid ones under ``rigid``."""
        h, t = self.loop.handle, self.loop.transmission
        v = self.verdict
        return {
            "passive": v.passive,
            "model": MODEL,
            "criterion": v.criterion,
            "outcome": v.outcome,
            "margin": v.margin,
            "margin_units": MARGIN_UNITS,
            "critical_theta": v.critical_theta,
            "stable": v.stable,
            "spectral_radius": v.spectral_radius,
            "max_stiffness": self.max_stiffness,
            "max_stiffness_relative_tolerance": LIMIT_RELATIVE,
            "parameters": {"m": h.m, "b": h.b, "T": h.T, "K": h.K, "B": h.B, "delay": h.delay, "velocity": str(h.velocity)},
            "transmission": {**t.to_dict(), "resonance_hz": t.resonance(h.m)},
            "rigid": {name: {"passive": r.passive, "margin": r.margin, "outcome": r.outcome, "mass": mass}
                      for name, r, mass in (("handle_alone", self.handle_alone, h.m),
                                            ("rigid_limit", self.rigid_limit, h.m + t.motor_mass))},
        }


def check_two_mass(mass: float, friction: float, period: float, stiffness: float, damping: float, delay: float,
                   velocity: VelocityModel | str, transmission: Transmission) -> TwoMassReport:
    """Is the wall ``K`` N/m, ``B`` N s/m passive on a handle ``m`` kg, ``b`` N s/m coupled by ``transmission`` to its
    motor, sampled every ``T`` s with ``delay`` samples and the drive's ``velocity`` model?  ParameterError naming
    a parameter as the command line spells it."""
    try:
        handle = WallLoop(mass, friction, period, stiffness, damping, delay, VelocityModel.parse(velocity))
    except ParameterError as error:
        raise ParameterError(WORDS.get(error.name, error.name), error.value, error.allowed, error.context) from None
    return check_two_mass_loop(TwoMassLoop(handle, transmission))


def check_two_mass_loop(loop: TwoMassLoop) -> TwoMassReport:
    """The :class:`TwoMassReport` of ``loop`` (what ``haptic-bus profiles check`` shows for a profile with
    ``[device.transmission]``)."""
    return TwoMassReport(loop, two_mass_verdict(loop), largest_passive_stiffness(loop, LIMIT_RELATIVE),
                         exact_verdict(loop.handle), exact_verdict(loop.rigid))


def _state(verdict: Verdict) -> str:
    if verdict.lossless:
        return "marginally stable: the pair's translation (z = 1), no mode grows"
    if verdict.marginal:
        return "marginally stable: a pole on the unit circle (not strictly inside: not passive)"
    return "stable" if verdict.stable else "UNSTABLE"


def _short(verdict: Verdict) -> str:
    return f"{verdict.outcome}, margin {verdict.margin:+.6g} N s/m"


def format_two_mass(report: TwoMassReport) -> str:
    """Human-readable lines of a :class:`TwoMassReport`."""
    h, t = report.loop.handle, report.loop.transmission
    v = report.verdict
    largest = ("none (not even K = 0)" if report.max_stiffness is None else
               f"{report.max_stiffness:.7g} N/m (bisection to {LIMIT_RELATIVE:g} relative, from K = 0)")
    margin = ("margin none: Re Z >= 0 decides nothing without strict stability" if v.marginal else
              f"margin {v.margin:+.6g} N s/m at theta = {v.critical_theta:.6g} rad"
              + (f" ({v.critical_theta / (2 * math.pi * h.T):.4g} Hz)" if v.critical_theta > 0 else ""))
    return "\n".join([
        f"loop: m={h.m:g} kg (handle)  b={h.b:g} N s/m (at the handle)  T={h.T:g} s  K={h.K:g} N/m  B={h.B:g} N s/m"
        f"  delay={h.delay:g} samples  velocity={h.velocity} (of the motor)",
        f"transmission: {t.describe()}; free resonance {t.resonance(h.m):.4g} Hz",
        f"model: {MODEL}",
        f"verdict: {'passive' if v.passive else 'NOT passive'}  ({v.criterion}; operator forces below Nyquist)",
        f"  {margin}; closed loop {_state(v)} (largest |pole| {v.spectral_radius:.9g})",
        f"passive K at this B (two-mass): up to {largest}",
        f"rigid criterion on the handle alone (m = {h.m:g} kg, no transmission): {_short(report.handle_alone)}",
        f"rigid limit (stiffness -> infinity, m + motor mass = {h.m + t.motor_mass:g} kg): {_short(report.rigid_limit)}",
    ])
