"""High-precision (mpmath) references of the wall loop's frequency responses, straight from
their definitions (no reformulation), for checking the double-precision analysis.

The definitions (every velocity model, every real delay) live in
:mod:`haptic_bus.bench.mp_boundary`; here they are evaluated at 80 digits.
"""

from __future__ import annotations

import mpmath as mp

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.bench.mp_boundary import response_terms

DIGITS = 80


def t_fund_mp(loop: WallLoop, theta, K=None, B=None) -> mp.mpc:
    """``T_fund = G11 [1 - (H/T) e^{-j w D T} K_d M G11 / (1 + G_md K_d)]`` in m/(N s), 80 digits."""
    with mp.workdps(DIGITS):
        g11, g_md, wall, path = response_terms(loop, theta, K, B)
        return g11 * (1 - path * wall * g11 / (1 + g_md * wall))


def t_zw_mp(loop: WallLoop, theta) -> mp.mpc:
    """The seed's ``G11 / (1 + G_md K_d)`` in m/(N s), 80 digits."""
    with mp.workdps(DIGITS):
        g11, g_md, wall, _ = response_terms(loop, theta)
        return g11 / (1 + g_md * wall)


def re_z_mp(loop: WallLoop, theta, K=None, B=None) -> mp.mpf:
    """``Re(1/T_fund)`` in N s/m, 80 digits."""
    with mp.workdps(DIGITS):
        return mp.re(1 / t_fund_mp(loop, theta, K, B))
