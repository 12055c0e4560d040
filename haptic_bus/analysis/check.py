"""What ``haptic-bus check`` reports: every criterion's verdict and margin, the limits, the rule."""

from __future__ import annotations

import math
from typing import Any

from haptic_bus.analysis.closed_form import colgate_slack, liu2011_slack, velocity_sampling_slack
from haptic_bus.analysis.criterion import EXACT, exact_verdict, seed_verdict
from haptic_bus.analysis.limits import RELATIVE_TOLERANCE, max_damping, max_stiffness
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import closed_loop_poles

BANDWIDTH_ALPHA = 6.0


def check_report(loop: WallLoop) -> dict[str, Any]:
    """A JSON-ready report of the loop's passivity (margins in N s/m, limits in N/m and N s/m)."""
    exact = exact_verdict(loop)
    seed = seed_verdict(loop)
    alpha = loop.alpha
    poles = closed_loop_poles(loop)
    return {
        "passive": exact.passive,
        "criterion": EXACT,
        "margin": exact.margin,
        "margin_units": "N s/m (least Re of the impedance 1/T_fund the operator feels; >= 0 iff passive)",
        "critical_theta": exact.critical_theta,
        "stable": exact.stable,
        "spectral_radius": exact.spectral_radius,
        "max_stiffness": max_stiffness(loop),
        "max_damping": max_damping(loop),
        "limits_relative_tolerance": RELATIVE_TOLERANCE,
        "parameters": {"m": loop.m, "b": loop.b, "T": loop.T, "K": loop.K, "B": loop.B, "delay": loop.delay},
        "closed_loop_poles": [[float(p.real), float(p.imag)] for p in poles],
        "seed_t_zw": {"passive": seed.passive, "margin": seed.margin, "critical_theta": seed.critical_theta},
        "closed_forms": {
            "velocity_sampling_eq23": {"holds": velocity_sampling_slack(loop) >= 0, "slack": velocity_sampling_slack(loop),
                                       "applies": loop.delay == 0},
            "position_colgate_eq2": {"holds": colgate_slack(loop) >= 0, "slack": colgate_slack(loop)},
            "position_liu2011_eq4": {"holds": liu2011_slack(loop) >= 0, "slack": liu2011_slack(loop)},
        },
        "bandwidth_rule": {"alpha": alpha if math.isfinite(alpha) else None, "required": BANDWIDTH_ALPHA,
                           "holds": alpha > BANDWIDTH_ALPHA},
    }


def _yes(flag: bool) -> str:
    return "passive" if flag else "NOT passive"


def format_check(report: dict[str, Any]) -> str:
    """Human-readable lines of :func:`check_report`."""
    p = report["parameters"]
    forms = report["closed_forms"]
    seed = report["seed_t_zw"]
    k_max, b_max = report["max_stiffness"], report["max_damping"]
    rule = report["bandwidth_rule"]
    alpha = "inf" if rule["alpha"] is None else f"{rule['alpha']:.4g}"
    lines = [
        f"loop: m={p['m']:g} kg  b={p['b']:g} N s/m  T={p['T']:g} s  K={p['K']:g} N/m  B={p['B']:g} N s/m  delay={p['delay']} samples",
        f"verdict: {_yes(report['passive'])}  ({report['criterion']})",
        f"  margin {report['margin']:+.6g} N s/m at theta = {report['critical_theta']:.6g} rad;"
        f" closed loop {'stable' if report['stable'] else 'UNSTABLE'} (largest |pole| {report['spectral_radius']:.9g})",
        f"seed T_zw (eq. 11): {_yes(seed['passive'])}, margin {seed['margin']:+.6g} N s/m at theta = {seed['critical_theta']:.6g}",
        f"eq. 23 velocity sampling: {'holds' if forms['velocity_sampling_eq23']['holds'] else 'fails'},"
        f" slack {forms['velocity_sampling_eq23']['slack']:+.6g} N s/m"
        + ("" if forms["velocity_sampling_eq23"]["applies"] else " (ignores the loop delay)"),
        f"eq. 2 Colgate (position sampling): {'holds' if forms['position_colgate_eq2']['holds'] else 'fails'};"
        f" eq. 4 Liu 2011 (position sampling): {'holds' if forms['position_liu2011_eq4']['holds'] else 'fails'}",
        f"largest passive K at this B: {'none' if k_max is None else f'{k_max:.9g} N/m'};"
        f" largest passive B at this K: {'none' if b_max is None else f'{b_max:.9g} N s/m'}"
        f" (relative tolerance {report['limits_relative_tolerance']:g})",
        f"bandwidth rule alpha = B/(K T) = {alpha} {'>' if rule['holds'] else '<='} 6: {'ok' if rule['holds'] else 'violated'}",
    ]
    return "\n".join(lines)
