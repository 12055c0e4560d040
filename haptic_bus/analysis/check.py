"""One wall loop judged by every criterion: what ``haptic-bus check`` and ``check_passivity`` report.

:func:`check_passivity` returns a frozen :class:`CheckReport`; ``report.to_dict()`` is the
JSON ``haptic-bus check --json`` prints and ``format_check(report)`` the text it prints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from haptic_bus.analysis.closed_form import colgate_slack, liu2011_slack, velocity_sampling_slack
from haptic_bus.analysis.criterion import EXACT, exact_verdict, seed_verdict
from haptic_bus.analysis.limits import RELATIVE_TOLERANCE, max_damping, max_stiffness
from haptic_bus.analysis.loop import BANDWIDTH_ALPHA, WallLoop
from haptic_bus.analysis.poles import closed_loop_poles

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
class CheckReport:
    """A wall loop's passivity by every criterion.

    ``passive``/``margin`` (N s/m)/``critical_theta`` (rad) are the exact criterion's (the one
    the gate uses); ``max_stiffness`` (N/m) and ``max_damping`` (N s/m) the largest passive
    ``K`` at this ``B`` and ``B`` at this ``K`` (None: no passive value); ``closed_loop_poles``
    in the z-plane, largest magnitude first; ``alpha = B/(K T)`` (inf for K = 0) against the
    seed's bandwidth rule ``alpha > 6``.
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
    criterion: str = EXACT
    limits_relative_tolerance: float = RELATIVE_TOLERANCE

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
            "max_stiffness": self.max_stiffness,
            "max_damping": self.max_damping,
            "limits_relative_tolerance": self.limits_relative_tolerance,
            "parameters": {"m": loop.m, "b": loop.b, "T": loop.T, "K": loop.K, "B": loop.B, "delay": loop.delay},
            "closed_loop_poles": [[p.real, p.imag] for p in self.closed_loop_poles],
            "seed_t_zw": {"passive": self.seed.passive, "margin": self.seed.margin,
                          "critical_theta": self.seed.critical_theta},
            "closed_forms": {
                name: {"holds": form.holds, "slack": form.slack, **({"applies": form.applies} if name.startswith("velocity") else {})}
                for name, form in (("velocity_sampling_eq23", self.velocity_sampling_eq23),
                                   ("position_colgate_eq2", self.position_colgate_eq2),
                                   ("position_liu2011_eq4", self.position_liu2011_eq4))
            },
            "bandwidth_rule": {"alpha": self.alpha if math.isfinite(self.alpha) else None, "required": BANDWIDTH_ALPHA,
                               "holds": self.bandwidth_rule_holds},
        }


def check_loop(loop: WallLoop) -> CheckReport:
    """Judge ``loop`` by every criterion (exact, seed, closed forms), with its limits and poles."""
    exact = exact_verdict(loop)
    seed = seed_verdict(loop)
    eq23, eq2, eq4 = velocity_sampling_slack(loop), colgate_slack(loop), liu2011_slack(loop)
    return CheckReport(
        loop=loop,
        passive=exact.passive,
        margin=exact.margin,
        critical_theta=exact.critical_theta,
        stable=exact.stable,
        spectral_radius=exact.spectral_radius,
        max_stiffness=max_stiffness(loop),
        max_damping=max_damping(loop),
        closed_loop_poles=tuple(complex(p) for p in closed_loop_poles(loop)),
        seed=SeedCheck(seed.passive, seed.margin, seed.critical_theta),
        velocity_sampling_eq23=ClosedForm(eq23 >= 0, eq23, applies=loop.delay == 0),
        position_colgate_eq2=ClosedForm(eq2 >= 0, eq2),
        position_liu2011_eq4=ClosedForm(eq4 >= 0, eq4),
        alpha=loop.alpha,
    )


def check_passivity(mass: float, friction: float, period: float, stiffness: float, damping: float,
                    delay: int = 0) -> CheckReport:
    """Is a wall ``K`` (N/m), ``B`` (N s/m) passive on a handle ``m`` (kg), ``b`` (N s/m) sampled
    every ``T`` (s) with a loop delay of ``delay`` samples?  Every criterion's answer.

    Raises :class:`~drives.errors.ParameterError` naming a parameter outside its range.
    """
    return check_loop(WallLoop(mass, friction, period, stiffness, damping, delay))


def _yes(flag: bool) -> str:
    return "passive" if flag else "NOT passive"


def format_check(report: CheckReport) -> str:
    """Human-readable lines of a :class:`CheckReport`."""
    p = report.loop
    eq23 = report.velocity_sampling_eq23
    k_max, b_max = report.max_stiffness, report.max_damping
    alpha = "inf" if not math.isfinite(report.alpha) else f"{report.alpha:.4g}"
    holds = report.bandwidth_rule_holds
    lines = [
        f"loop: m={p.m:g} kg  b={p.b:g} N s/m  T={p.T:g} s  K={p.K:g} N/m  B={p.B:g} N s/m  delay={p.delay} samples",
        f"verdict: {_yes(report.passive)}  ({report.criterion})",
        f"  margin {report.margin:+.6g} N s/m at theta = {report.critical_theta:.6g} rad;"
        f" closed loop {'stable' if report.stable else 'UNSTABLE'} (largest |pole| {report.spectral_radius:.9g})",
        f"seed T_zw (eq. 11): {_yes(report.seed.passive)}, margin {report.seed.margin:+.6g} N s/m at theta = "
        f"{report.seed.critical_theta:.6g}",
        f"eq. 23 velocity sampling: {'holds' if eq23.holds else 'fails'}, slack {eq23.slack:+.6g} N s/m"
        + ("" if eq23.applies else " (ignores the loop delay)"),
        f"eq. 2 Colgate (position sampling): {'holds' if report.position_colgate_eq2.holds else 'fails'};"
        f" eq. 4 Liu 2011 (position sampling): {'holds' if report.position_liu2011_eq4.holds else 'fails'}",
        f"largest passive K at this B: {'none' if k_max is None else f'{k_max:.9g} N/m'};"
        f" largest passive B at this K: {'none' if b_max is None else f'{b_max:.9g} N s/m'}"
        f" (relative tolerance {report.limits_relative_tolerance:g})",
        f"bandwidth rule alpha = B/(K T) = {alpha} {'>' if holds else '<='} 6: {'ok' if holds else 'violated'}",
    ]
    return "\n".join(lines)
