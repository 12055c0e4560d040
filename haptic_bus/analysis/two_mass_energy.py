"""Time-domain energy check of the two-mass loop (DESIGN 3.4): the arbiter of its criterion.

The loop as it runs: the two-mass plant of :mod:`haptic_bus.analysis.two_mass` (handle, coupling,
motor), the drive sensing the motor by the velocity model and holding the wall's force on the
motor with the loop's delay, the operator's force at the handle.  The machine is the rigid
check's (:class:`~haptic_bus.analysis.energy.LoopMachine`: the plant with a tone generator in one
linear ODE, its solution and the operator's work ``int w v_handle dt`` over every piece of a period
from one matrix exponential each, ``scipy.linalg.expm``) with the two-mass plant given as its model:
nothing here uses the frequency-domain formulas.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from haptic_bus.analysis.energy import LoopMachine, OperatorForce, Sinusoid, commensurate_theta, periodic_mean_power
from haptic_bus.analysis.two_mass import TwoMassLoop, two_mass_model, two_mass_stability
from haptic_bus.analysis.two_mass_criterion import t_fund_two_mass
from haptic_bus.errors import ParameterError


def two_mass_machine(loop: TwoMassLoop, force: OperatorForce) -> LoopMachine:
    """The two-mass loop driven from rest by ``force`` (N, at the handle): its period matrix and work per piece."""
    return LoopMachine(loop.rigid, force.tones(), 1, two_mass_model(loop))


class TwoMassPower(NamedTuple):
    """Mean operator power (W) of ``amplitude sin(omega t)`` in the periodic steady state, at the
    ``theta`` used (``2 pi p/q``, ``q`` = ``window`` samples), and its prediction ``A^2 Re T_fund/2`` (W)."""

    power: float
    predicted: float
    theta: float
    window: int


def two_mass_mean_power(loop: TwoMassLoop, theta: float, amplitude: float = 1.0, max_samples: int = 4096) -> TwoMassPower:
    """The exact steady-state mean power of a tone at ``theta`` (rad, rounded to repeat within ``max_samples``),
    beside the criterion's prediction.  Needs a stable loop."""
    if two_mass_stability(loop)[0] != "stable":
        raise ParameterError("loop", loop, "a stable two-mass loop (closed-loop spectral radius < 1) for a steady state")
    p, q = commensurate_theta(theta, max_samples)
    used = 2 * math.pi * p / q
    power = periodic_mean_power(loop.rigid, Sinusoid(used, loop.rigid.T, amplitude), q, two_mass_model(loop))
    predicted = 0.5 * amplitude**2 * float(t_fund_two_mass(loop, used)[0].real)
    return TwoMassPower(power, predicted, used, q)
