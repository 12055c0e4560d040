"""The seed's three closed-form passivity conditions, physical and ``alpha``-``beta`` forms.

``alpha = B / (K T)``, ``beta = b / B``.  Each physical function returns the *slack* in
N s/m: ``b`` minus the damping the condition requires, so ``slack >= 0`` means the
condition holds and its size says by how much.  The ``alpha``-``beta`` functions return the
boundary ``beta`` (above it: passive) and are vectorised.

| sampling                   | condition                          | seed eq. |
|----------------------------|------------------------------------|----------|
| position, Colgate-Schenkel | ``b >= KT/2 + B``                  | (2), (3) |
| position, Liu 2011         | ``b >= (KT + B)/2``                | (4), (5) |
| velocity (the seed)        | ``b >= tanh(bT/(2m)) (KT/2 + B)``  | (23),(24)|

``(1 - e^-x)/(1 + e^-x) = tanh(x/2)`` exactly; ``tanh`` does not cancel where the quotient does.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.loop import WallLoop


def colgate_slack(loop: WallLoop) -> float:
    """Eq. (2), position sampling (Colgate-Schenkel): ``b - (KT/2 + B)`` in N s/m."""
    return loop.b - (0.5 * loop.K * loop.T + loop.B)


def liu2011_slack(loop: WallLoop) -> float:
    """Eq. (4), position sampling (Liu 2011): ``b - (KT + B)/2`` in N s/m."""
    return loop.b - 0.5 * (loop.K * loop.T + loop.B)


def velocity_sampling_factor(c: float) -> float:
    """``(1 - e^-c)/(1 + e^-c) = tanh(c/2)`` with ``c = bT/m`` (dimensionless)."""
    return math.tanh(0.5 * c)


def velocity_sampling_slack(loop: WallLoop) -> float:
    """Eq. (23), velocity sampling (the seed): ``b - tanh(bT/2m)(KT/2 + B)`` in N s/m."""
    return loop.b - velocity_sampling_factor(loop.c) * (0.5 * loop.K * loop.T + loop.B)


def colgate_beta(alpha: ArrayLike) -> np.ndarray:
    """Eq. (3): boundary ``beta = 1/(2 alpha) + 1``."""
    return 0.5 / np.asarray(alpha, dtype=float) + 1.0


def liu2011_beta(alpha: ArrayLike) -> np.ndarray:
    """Eq. (5): boundary ``beta = 1/(2 alpha) + 1/2``."""
    return 0.5 / np.asarray(alpha, dtype=float) + 0.5


def velocity_sampling_beta(alpha: ArrayLike, c: ArrayLike) -> np.ndarray:
    """Eq. (24): boundary ``beta = tanh(c/2) (1/(2 alpha) + 1)``, ``c = bT/m``."""
    return np.tanh(0.5 * np.asarray(c, dtype=float)) * (0.5 / np.asarray(alpha, dtype=float) + 1.0)


def region_map(alpha: ArrayLike, beta: ArrayLike, c: float) -> np.ndarray:
    """Boolean map: ``True`` where ``(alpha, beta)`` satisfies eq. (24) for ``c = bT/m``.

    Broadcasts ``alpha`` against ``beta`` (e.g. a meshgrid); note that eq. (24) in these
    coordinates still needs ``c``, because ``b`` appears on both sides of eq. (23).
    """
    return np.asarray(beta, dtype=float) >= velocity_sampling_beta(alpha, c)
