"""One wall loop judged by every criterion: what ``haptic-bus check`` and ``check_passivity`` report.

:func:`check_passivity` returns a frozen :class:`CheckReport`; ``report.to_dict()`` is the
JSON ``haptic-bus check --json`` prints and ``format_check(report)`` the text it prints.

The exact verdict, the seed's test and every end of the passive ``K`` and ``B`` intervals are
zoomed jointly (:func:`~haptic_bus.analysis.theta_search.refine_lanes`): one evaluation of the
loop's terms on the grid and one per zoom round serve them all.  Asked for (``check_loop``'s
default, what ``haptic-bus check`` and ``report`` show; ``check_passivity(..., out_of_band=True)``),
the report carries the loop's out-of-band exposure
(:mod:`haptic_bus.analysis.out_of_band`): the worst mean power a force with content above Nyquist
-- a tone and one alias, and up to ``N`` aliases -- can take out.
Importing this module loads numpy only (no scipy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from haptic_bus.analysis.closed_form import colgate_slack, liu2011_slack, velocity_sampling_slack
from haptic_bus.analysis.criterion import (
    EXACT,
    Verdict,
    impedance_group,
    judge,
    lossless_verdict,
    seed_judgement,
    seed_lane,
    verdict_lane,
)
from haptic_bus.analysis.frequency import grid_terms, loop_terms
from haptic_bus.analysis.limits import RELATIVE_TOLERANCE, LimitsPlan, PassiveSet
from haptic_bus.analysis.loop import BANDWIDTH_ALPHA, WORDS, WallLoop
from haptic_bus.analysis.out_of_band import DEFAULT_HARMONICS, Exposure, worst_force
from haptic_bus.analysis.poles import closed_loop_poles, stability
from haptic_bus.analysis.quantisation import QuantisationCondition, quantisation_condition, quantised_ceiling
from haptic_bus.analysis.resolution import Quantisation
from haptic_bus.analysis.theta_search import refine_lanes
from haptic_bus.analysis.velocity import POINT, VelocityModel
from haptic_bus.errors import ParameterError

MARGIN_UNITS = "N s/m (least Re of the impedance 1/T_fund the operator feels; >= 0 iff passive)"


@dataclass(frozen=True)
class SeedCheck:
    """The seed's own frequency test ``Re T_zw >= 0`` (no stability test): margin in N s/m."""

    passive: bool
    margin: float
    critical_theta: float


@dataclass(frozen=True)
class ClosedForm:
    """One closed-form condition: whether it holds, its slack in N s/m, and whether it applies
    to the loop (eq. 23 ignores a loop delay)."""

    holds: bool
    slack: float
    applies: bool = True


@dataclass(frozen=True)
class OutOfBand:
    """Exposure to operator forces above Nyquist (None for a loop that is not stable: no steady state).

    ``pair``: the worst tone below Nyquist plus one alias; ``harmonics``: the worst force made
    of up to ``N`` aliases each side (W per N^2 of force, ``sum A^2 = 1``; < 0: energy out).
    """

    pair: Exposure
    harmonics: Exposure


@dataclass(frozen=True)
class CheckReport:
    """A wall loop's passivity by every criterion.

    ``passive``/``margin`` (N s/m)/``critical_theta`` (rad) are the exact criterion's (the one
    the gate uses), ``outcome`` its name ("passive", "lossless", "lossless oscillator",
    "marginal", "not passive", "unstable"); ``stiffness_set`` (N/m) and ``damping_set`` (N s/m)
    every passive ``K`` at this ``B`` and ``B`` at this ``K`` (intervals with their open or
    closed ends, not necessarily from 0), ``max_stiffness`` and ``max_damping`` their upper ends
    (None: no passive value; at least that, where the set reaches the input ceiling);
    ``closed_loop_poles`` in the z-plane, largest magnitude first, ``poles_extended`` True when
    50-digit arithmetic judged them; ``alpha = B/(K T)`` (inf for K = 0) against the seed's
    bandwidth rule ``alpha > 6``; ``out_of_band`` the exposure above Nyquist (None when not
    asked, ``out_of_band_asked``, or the loop is not stable); ``quantisation`` the encoder
    quantisation and Coulomb friction condition (:mod:`haptic_bus.analysis.quantisation`; None
    when not asked): ``passive`` needs it to hold too.
    """

    loop: WallLoop
    passive: bool
    margin: float
    critical_theta: float
    stable: bool
    spectral_radius: float
    max_stiffness: float | None
    max_damping: float | None
    closed_loop_poles: tuple[complex, ...]
    seed: SeedCheck
    velocity_sampling_eq23: ClosedForm
    position_colgate_eq2: ClosedForm
    position_liu2011_eq4: ClosedForm
    alpha: float
    stiffness_set: PassiveSet
    damping_set: PassiveSet
    outcome: str
    out_of_band: OutOfBand | None
    criterion: str = EXACT
    limits_relative_tolerance: float = RELATIVE_TOLERANCE
    out_of_band_asked: bool = True
    poles_extended: bool = False
    quantisation: QuantisationCondition | None = None

    @property
    def lossless(self) -> bool:
        """The free frictionless mass (``b = K = B = 0``): passive, marginally stable."""
        return self.outcome == "lossless"

    @property
    def bandwidth_rule_holds(self) -> bool:
        """The seed's design rule ``alpha = B/(K T) > 6``."""
        return self.alpha > BANDWIDTH_ALPHA

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: plain numbers, poles as ``[re, im]`` pairs, ``alpha`` None when infinite."""
        loop = self.loop
        return {
            "passive": self.passive,
            "criterion": self.criterion,
            "margin": self.margin,
            "margin_units": MARGIN_UNITS,
            "critical_theta": self.critical_theta,
            "stable": self.stable,
            "spectral_radius": self.spectral_radius,
            "outcome": self.outcome,
            "lossless": self.lossless,
            "max_stiffness": self.max_stiffness,
            "max_damping": self.max_damping,
            "stiffness_passive": self.stiffness_set.to_dict(),
            "damping_passive": self.damping_set.to_dict(),
            "limits_relative_tolerance": self.limits_relative_tolerance,
            "parameters": {"m": loop.m, "b": loop.b, "T": loop.T, "K": loop.K, "B": loop.B, "delay": loop.delay,
                           "velocity": str(loop.velocity)},
            "out_of_band": None if self.out_of_band is None else {
                "pair": self.out_of_band.pair.to_dict(), "harmonics": self.out_of_band.harmonics.to_dict(),
                "units": "W per N^2 of operator force (sum of squared tone amplitudes = 1 N^2); power < 0: energy out"},
            "closed_loop_poles": [[p.real, p.imag] for p in self.closed_loop_poles],
            "poles_extended_precision": self.poles_extended,
            "seed_t_zw": {"passive": self.seed.passive, "margin": self.seed.margin,
                          "critical_theta": self.seed.critical_theta},
            "closed_forms": {
                name: {"holds": form.holds, "slack": form.slack,
                       **({"applies": form.applies} if name.startswith("velocity") else {})}
                for name, form in (("velocity_sampling_eq23", self.velocity_sampling_eq23),
                                   ("position_colgate_eq2", self.position_colgate_eq2),
                                   ("position_liu2011_eq4", self.position_liu2011_eq4))
            },
            "bandwidth_rule": {"alpha": self.alpha if math.isfinite(self.alpha) else None, "required": BANDWIDTH_ALPHA,
                               "holds": self.bandwidth_rule_holds},
            "quantisation": None if self.quantisation is None else self.quantisation.to_dict(),
        }


def _verdicts(loop: WallLoop) -> tuple[Verdict, Verdict, PassiveSet, PassiveSet]:
    """(exact verdict, seed's verdict, passive K, passive B): one grid, one joint zoom."""
    terms = grid_terms(loop, closed_loop_poles(loop))
    grid = terms.theta
    group = impedance_group(loop, seed=True)
    plan = LimitsPlan(loop, ("K", "B"), terms)
    data = group.evaluate(terms)
    lanes = [verdict_lane(data), seed_lane(data), *plan.lanes]
    minima = refine_lanes(grid, lanes, {"impedance": group, **plan.groups}, lambda theta: loop_terms(loop, theta))
    exact = lossless_verdict() if loop.lossless else judge(loop, stability(loop), minima[0])
    stiffness, damping = plan.finish(minima[2:])
    return exact, seed_judgement(loop, minima[1]), stiffness, damping


def check_loop(loop: WallLoop, harmonics: int = DEFAULT_HARMONICS, out_of_band: bool = True,
               quantisation: Quantisation | None = None) -> CheckReport:
    """Judge ``loop`` by every criterion (exact, seed, closed forms), with its limits and poles, and
    (``out_of_band``, what ``haptic-bus check``, ``report`` and ``profiles check`` show) its
    out-of-band exposure (aliases up to ``harmonics`` each side); with ``quantisation``, also the
    quantisation condition, which the verdict then needs too."""
    exact, seed, stiffness, damping = _verdicts(loop)
    condition = None if quantisation is None else quantisation_condition(loop, quantisation)
    if quantisation is not None:  # the limits the verdict needs: the exact criterion's and the quantisation's
        stiffness = stiffness.at_most(quantised_ceiling(loop, quantisation, "K"))
        damping = damping.at_most(quantised_ceiling(loop, quantisation, "B"))
    quantised_out = exact.passive and condition is not None and not condition.holds
    eq23, eq2, eq4 = velocity_sampling_slack(loop), colgate_slack(loop), liu2011_slack(loop)
    exposure = None
    if out_of_band and exact.stable:
        exposure = OutOfBand(worst_force(loop, harmonics, pair=True), worst_force(loop, harmonics))
    return CheckReport(
        loop=loop,
        passive=exact.passive and not quantised_out,
        margin=exact.margin,
        critical_theta=exact.critical_theta,
        stable=exact.stable,
        spectral_radius=exact.spectral_radius,
        max_stiffness=stiffness.largest,
        max_damping=damping.largest,
        closed_loop_poles=tuple(complex(p) for p in closed_loop_poles(loop)),
        seed=SeedCheck(seed.passive, seed.margin, seed.critical_theta),
        velocity_sampling_eq23=ClosedForm(eq23 >= 0, eq23, applies=loop.delay == 0 and loop.velocity == POINT),
        position_colgate_eq2=ClosedForm(eq2 >= 0, eq2),
        position_liu2011_eq4=ClosedForm(eq4 >= 0, eq4),
        alpha=loop.alpha,
        stiffness_set=stiffness,
        damping_set=damping,
        outcome="not passive" if quantised_out else exact.outcome,
        out_of_band=exposure,
        out_of_band_asked=out_of_band,
        poles_extended=stability(loop).extended,
        quantisation=condition,
    )


def check_passivity(mass: float, friction: float, period: float, stiffness: float, damping: float,
                    delay: float = 0, velocity: VelocityModel | str = "point", out_of_band: bool = False,
                    position_resolution: float | None = None, coulomb: float = 0.0,
                    velocity_resolution: float = 0.0) -> CheckReport:
    """Is a wall ``K`` (N/m), ``B`` (N s/m) passive on a handle ``m`` (kg), ``b`` (N s/m) sampled
    every ``T`` (s) with a loop delay of ``delay`` samples (real) and the drive's ``velocity``
    model (``"point"``, ``"average"``, ``"window:SECONDS"``, ``"lowpass:SECONDS"``)?  Every
    criterion's answer, the passive intervals, and (``out_of_band``) the exposure above Nyquist.
    With a ``position_resolution`` (m per 0x6064 increment; or a ``velocity_resolution``, m/s
    per 0x606C unit) the verdict needs the quantisation condition with the Coulomb friction
    ``coulomb`` (N) too (:mod:`haptic_bus.analysis.quantisation`).

    Raises :class:`~haptic_bus.errors.ParameterError` naming a parameter outside its range.
    """
    try:
        loop = WallLoop(mass, friction, period, stiffness, damping, delay, VelocityModel.parse(velocity))
    except ParameterError as error:  # named as the caller spelled it
        raise ParameterError(WORDS.get(error.name, error.name), error.value, error.allowed, error.context) from None
    asked = position_resolution is not None or velocity_resolution != 0.0
    quantisation = Quantisation(position_resolution or 0.0, coulomb, velocity_resolution) if asked else None
    return check_loop(loop, out_of_band=out_of_band, quantisation=quantisation)


def _yes(flag: bool) -> str:
    return "passive" if flag else "NOT passive"


def _exposure_text(exposure: Exposure) -> str:
    tones = " + ".join(f"{a:.3g} N at {f:.6g} Hz" for f, a in zip(exposure.frequencies, exposure.amplitudes))
    return f"{exposure.power:+.4g} W per N^2 ({tones})"


def _exposure_meaning(power: float) -> str:
    """What the sign of the worst out-of-band force's mean power (W per N^2) means for the operator."""
    return "< 0: the operator can take energy out" if power < 0 else ">= 0: none of these forces takes energy out"


def format_check(report: CheckReport) -> str:
    """Human-readable lines of a :class:`CheckReport`."""
    p = report.loop
    eq23 = report.velocity_sampling_eq23
    alpha = "inf" if not math.isfinite(report.alpha) else f"{report.alpha:.4g}"
    holds = report.bandwidth_rule_holds
    on_circle = report.outcome in ("lossless oscillator", "marginal")
    if report.lossless:
        state = "marginally stable: lossless, its only mode is the constant velocity (z = 1)"
    elif report.outcome == "lossless oscillator":
        state = ("marginally stable: a lossless oscillator, its poles on the unit circle (product 1); not strictly "
                 "inside, so the strict rule does not call it passive")
    elif report.outcome == "marginal":
        state = "marginally stable: a pole on the unit circle (not strictly inside: not passive)"
    else:
        state = "stable" if report.stable else "UNSTABLE"
    extended = "; judged in 50-digit arithmetic (within round-off of the circle in double)" if report.poles_extended else ""
    margin = ("margin none: Re Z >= 0 decides nothing without strict stability" if on_circle else
              f"margin {report.margin:+.6g} N s/m at theta = {report.critical_theta:.6g} rad")
    verdict = "passive (lossless)" if report.lossless else _yes(report.passive)
    quantised = report.quantisation
    if quantised is not None and not quantised.holds:
        verdict += " (the quantisation condition fails)"
    if report.outcome == "lossless oscillator":
        verdict += " (lossless oscillator)"
    lines = [
        f"loop: m={p.m:g} kg  b={p.b:g} N s/m  T={p.T:g} s  K={p.K:g} N/m  B={p.B:g} N s/m  delay={p.delay:g} samples"
        f"  velocity={p.velocity}",
        f"verdict: {verdict}  ({report.criterion}; operator forces below Nyquist)",
        f"  {margin}; closed loop {state} (largest |pole| {report.spectral_radius:.9g}){extended}",
        f"seed T_zw (eq. 11): {_yes(report.seed.passive)}, margin {report.seed.margin:+.6g} N s/m at theta = "
        f"{report.seed.critical_theta:.6g}",
        f"eq. 23 velocity sampling: {'holds' if eq23.holds else 'fails'}, slack {eq23.slack:+.6g} N s/m"
        + ("" if eq23.applies else " (ignores the loop delay)"),
        f"eq. 2 Colgate (position sampling): {'holds' if report.position_colgate_eq2.holds else 'fails'};"
        f" eq. 4 Liu 2011 (position sampling): {'holds' if report.position_liu2011_eq4.holds else 'fails'}",
        f"passive K at this B: {report.stiffness_set.describe('N/m')};"
        f" passive B at this K: {report.damping_set.describe('N s/m')}"
        f" (relative tolerance {report.limits_relative_tolerance:g})",
        f"bandwidth rule alpha = B/(K T) = {alpha} {'>' if holds else '<='} 6: {'ok' if holds else 'violated'}",
    ]
    if quantised is not None:
        lines.append(quantised.describe())
    band = report.out_of_band
    if not report.out_of_band_asked:
        lines.append("out of band (above Nyquist): not asked")
    elif band is None:
        lines.append("out of band (above Nyquist): not applicable, the loop is not stable (no steady state)")
    else:
        lines.append(f"out of band (above Nyquist): worst pair {_exposure_text(band.pair)}")
        lines.append(f"  worst force of up to {band.harmonics.harmonics} aliases each side:"
                     f" {band.harmonics.power:+.4g} W per N^2 ({_exposure_meaning(band.harmonics.power)})")
    return "\n".join(lines)
