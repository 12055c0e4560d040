"""One wall loop judged by every criterion: what ``haptic-bus check`` and ``check_passivity`` report.

:func:`check_passivity` returns a frozen :class:`CheckReport`; ``report.to_dict()`` is the
JSON ``haptic-bus check --json`` prints and ``format_check(report)`` the text it prints.

Beside the band-limited verdict (operator forces below Nyquist) the report carries the loop's
out-of-band exposure (:mod:`haptic_bus.analysis.aliasing`): the worst mean power a force with
content above Nyquist -- a tone and one alias, and up to ``N`` aliases -- can take out.
Importing this module loads numpy only (no scipy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from haptic_bus.analysis.aliasing import DEFAULT_HARMONICS, Exposure, worst_force
from haptic_bus.analysis.closed_form import colgate_slack, liu2011_slack, velocity_sampling_slack
from haptic_bus.analysis.criterion import EXACT, exact_verdict, seed_verdict
from haptic_bus.analysis.limits import RELATIVE_TOLERANCE, PassiveSet, passive_limits
from haptic_bus.analysis.loop import BANDWIDTH_ALPHA, WallLoop
from haptic_bus.analysis.poles import closed_loop_poles
from haptic_bus.analysis.velocity import POINT, VelocityModel

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
    """Exposure to operator forces above Nyquist (None for an unstable loop: no steady state).

    ``pair``: the worst tone below Nyquist plus one alias; ``harmonics``: the worst force made
    of up to ``N`` aliases each side (W per N^2 of force, ``sum A^2 = 1``; < 0: energy out).
    """

    pair: Exposure
    harmonics: Exposure


@dataclass(frozen=True)
class CheckReport:
    """A wall loop's passivity by every criterion.

    ``passive``/``margin`` (N s/m)/``critical_theta`` (rad) are the exact criterion's (the one
    the gate uses), ``outcome`` its name ("passive", "lossless", "not passive", "unstable");
    ``stiffness_set`` (N/m) and ``damping_set`` (N s/m) every passive ``K`` at this ``B`` and
    ``B`` at this ``K`` (closed intervals, not necessarily from 0), ``max_stiffness`` and
    ``max_damping`` their upper ends (None: no passive value); ``closed_loop_poles`` in the
    z-plane, largest magnitude first; ``alpha = B/(K T)`` (inf for K = 0) against the seed's
    bandwidth rule ``alpha > 6``; ``out_of_band`` the exposure above Nyquist.
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
        }


def check_loop(loop: WallLoop, harmonics: int = DEFAULT_HARMONICS) -> CheckReport:
    """Judge ``loop`` by every criterion (exact, seed, closed forms), with its limits, poles and
    out-of-band exposure (aliases up to ``harmonics`` each side)."""
    exact = exact_verdict(loop)
    seed = seed_verdict(loop)
    eq23, eq2, eq4 = velocity_sampling_slack(loop), colgate_slack(loop), liu2011_slack(loop)
    stiffness, damping = passive_limits(loop)
    exposure = None
    if exact.stable:
        exposure = OutOfBand(worst_force(loop, harmonics, pair=True), worst_force(loop, harmonics))
    return CheckReport(
        loop=loop,
        passive=exact.passive,
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
        outcome=exact.outcome,
        out_of_band=exposure,
    )


def check_passivity(mass: float, friction: float, period: float, stiffness: float, damping: float,
                    delay: float = 0, velocity: VelocityModel | str = "point") -> CheckReport:
    """Is a wall ``K`` (N/m), ``B`` (N s/m) passive on a handle ``m`` (kg), ``b`` (N s/m) sampled
    every ``T`` (s) with a loop delay of ``delay`` samples (real) and the drive's ``velocity``
    model (``"point"``, ``"average"``, ``"window:SECONDS"``, ``"lowpass:SECONDS"``)?  Every
    criterion's answer.

    Raises :class:`~drives.errors.ParameterError` naming a parameter outside its range.
    """
    return check_loop(WallLoop(mass, friction, period, stiffness, damping, delay, VelocityModel.parse(velocity)))


def _yes(flag: bool) -> str:
    return "passive" if flag else "NOT passive"


def _interval_text(passive: PassiveSet, unit: str) -> str:
    if not passive.intervals:
        return "none"
    return " and ".join(f"[{lo:.9g}, {hi:.9g}]" for lo, hi in passive.intervals) + f" {unit}"


def _exposure_text(exposure: Exposure) -> str:
    tones = " + ".join(f"{a:.3g} N at {f:.6g} Hz" for f, a in zip(exposure.frequencies, exposure.amplitudes))
    return f"{exposure.power:+.4g} W per N^2 ({tones})"


def format_check(report: CheckReport) -> str:
    """Human-readable lines of a :class:`CheckReport`."""
    p = report.loop
    eq23 = report.velocity_sampling_eq23
    alpha = "inf" if not math.isfinite(report.alpha) else f"{report.alpha:.4g}"
    holds = report.bandwidth_rule_holds
    if report.lossless:
        state = "marginally stable: lossless, its only mode is the constant velocity (z = 1)"
    else:
        state = "stable" if report.stable else "UNSTABLE"
    lines = [
        f"loop: m={p.m:g} kg  b={p.b:g} N s/m  T={p.T:g} s  K={p.K:g} N/m  B={p.B:g} N s/m  delay={p.delay:g} samples"
        f"  velocity={p.velocity}",
        f"verdict: {'passive (lossless)' if report.lossless else _yes(report.passive)}  ({report.criterion};"
        " operator forces below Nyquist)",
        f"  margin {report.margin:+.6g} N s/m at theta = {report.critical_theta:.6g} rad;"
        f" closed loop {state} (largest |pole| {report.spectral_radius:.9g})",
        f"seed T_zw (eq. 11): {_yes(report.seed.passive)}, margin {report.seed.margin:+.6g} N s/m at theta = "
        f"{report.seed.critical_theta:.6g}",
        f"eq. 23 velocity sampling: {'holds' if eq23.holds else 'fails'}, slack {eq23.slack:+.6g} N s/m"
        + ("" if eq23.applies else " (ignores the loop delay)"),
        f"eq. 2 Colgate (position sampling): {'holds' if report.position_colgate_eq2.holds else 'fails'};"
        f" eq. 4 Liu 2011 (position sampling): {'holds' if report.position_liu2011_eq4.holds else 'fails'}",
        f"passive K at this B: {_interval_text(report.stiffness_set, 'N/m')};"
        f" passive B at this K: {_interval_text(report.damping_set, 'N s/m')}"
        f" (relative tolerance {report.limits_relative_tolerance:g})",
        f"bandwidth rule alpha = B/(K T) = {alpha} {'>' if holds else '<='} 6: {'ok' if holds else 'violated'}",
    ]
    band = report.out_of_band
    if band is None:
        lines.append("out of band (above Nyquist): not applicable, the loop is unstable")
    else:
        lines.append(f"out of band (above Nyquist): worst pair {_exposure_text(band.pair)}")
        lines.append(f"  worst force of up to {band.harmonics.harmonics} aliases each side:"
                     f" {band.harmonics.power:+.4g} W per N^2 (< 0: the operator can take energy out)")
    return "\n".join(lines)
