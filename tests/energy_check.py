"""The exact time-domain check the gates' agreement tests share (the coupled gate, the two-mass gate).

Each design runs from rest at ``T`` = 1 ms under every velocity model of :data:`MODELS` and the
delays of :data:`DELAYS` (samples).  The operator's energy (J) is taken at every piece boundary of
:data:`STEPS` periods (the caller's :func:`~haptic_bus.analysis.coupled_energy.simulate_energies`:
its least value and round-off bound per design), then after ``2^j`` periods up to
``2^DOUBLINGS`` by doubling (:func:`~haptic_bus.analysis.coupled_energy.energy_after`, with its own
round-off bounds).  :func:`bears_out` says whether that bears out a verdict.
"""

from __future__ import annotations

import math

import numpy as np

from haptic_bus.analysis.coupled_energy import PeriodMachine, energy_after

T = 1e-3
MODELS = ("point", "average", "window:0.0005", "lowpass:0.002")
DELAYS = (0.0, 0.5, 1.0, 1.5)
STEPS = 1000
DOUBLINGS = 30


def bears_out(machine: PeriodMachine, lowest: float, bound: float, passive: bool) -> bool:
    """Whether the energy from rest bears out the verdict ``passive``, beyond round-off either way.

    Passive: the stepping run's ``lowest`` energy (J) is at least ``-bound`` (its round-off, J), and
    every doubling's energy is finite and at least minus its own round-off.  Active: the energy goes
    below minus the round-off somewhere, stepping or doubling (a doubling below minus the larger of
    its own bound and ``bound``).  An unstable run may overflow while stepping (``bound`` not
    finite): then its doublings before the overflow decide.
    """
    stepped = bound if math.isfinite(bound) else 0.0
    if not passive and lowest < -stepped:
        return True
    energies, bounds = energy_after(machine, DOUBLINGS)
    finite = np.isfinite(energies)
    if passive:
        return lowest >= -stepped and bool(finite.all() and np.all(energies >= -bounds))
    return bool(np.any(energies[finite] < -np.maximum(bounds[finite], stepped)))
