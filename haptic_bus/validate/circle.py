"""The unit circle where the sampled responses are evaluated: ``z = e^{j theta}`` and ``z - 1``, ``theta = omega T`` (rad)."""

from __future__ import annotations

import numpy as np


def unit_circle(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(z, z - 1)`` at ``theta`` (rad), ``z - 1 = 2j sin(theta/2) e^{j theta/2}`` without cancellation."""
    return np.exp(1j * theta), 2j * np.sin(0.5 * theta) * np.exp(0.5j * theta)
