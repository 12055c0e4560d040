"""High-precision (mpmath) references of the wall loop's frequency responses, straight from
their definitions (no reformulation), for checking the double-precision analysis."""

from __future__ import annotations

import mpmath as mp

from haptic_bus.analysis.loop import WallLoop

mp.mp.dps = 60


def _terms(loop: WallLoop, theta):
    m, b, T, K, B = (mp.mpf(x) for x in (loop.m, loop.b, loop.T, loop.K, loop.B))
    theta = mp.mpf(theta)
    omega = theta / T
    z = mp.exp(1j * theta)
    g11 = 1 / (m * 1j * omega + b)
    a = mp.exp(-b * T / m)
    k1 = (1 - a) / b if b > 0 else T / m
    g11d = k1 / (z - a)
    wall = (K * T * z / (z - 1) + B) * z ** (-loop.delay)
    hold = (1 - mp.exp(-1j * theta)) / (1j * omega)
    return g11, g11d, wall, hold / T


def t_fund_mp(loop: WallLoop, theta) -> mp.mpc:
    """``G11 [1 - (H/T) K_d' G11 / (1 + G11d K_d')]`` in m/(N s), 60 digits."""
    g11, g11d, wall, hold = _terms(loop, theta)
    return g11 * (1 - hold * wall * g11 / (1 + g11d * wall))


def t_zw_mp(loop: WallLoop, theta) -> mp.mpc:
    """The seed's ``G11 / (1 + G11d K_d')`` in m/(N s), 60 digits."""
    g11, g11d, wall, _ = _terms(loop, theta)
    return g11 / (1 + g11d * wall)
