"""The coupled gate against the exact time-domain energy (issue 22): 100 random oblique walls.

Each design: 2 or 3 axes with their own ``m`` (0.1..3.2 kg) and ``b`` (1..32 N s/m), one
timing for all or each its own (velocity model point / average / window / lowpass, delay 0,
0.5, 1 or 1.5 samples), a plane wall with every normal component at least 0.3 of the largest,
``K`` 100..20 000 N/m, ``B`` 0..10 N s/m (seeded).  The operator pushes with the tone that
:func:`adversarial_input` picks from ``Herm Z``'s eigenvectors (``W = Z v`` at the frequency
that takes energy out fastest), from rest; energy at every piece boundary of 1 000 periods, then
after ``2^j`` periods up to ``2^30`` by doubling.  A passive design must never go below minus
the round-off bound; an active one must go below it somewhere.

The verdicts cost about 50 ms of CPU each (2-3 axes, three times a 1-D verdict); the 100
machines and the batched run about 2 s more.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from haptic_bus.analysis.coupled import CoupledVerdict, coupled_verdict
from haptic_bus.analysis.coupled_energy import CoupledMachine, adversarial_input, simulate_energies
from haptic_bus.analysis.coupled_loop import CoupledLoop, plane_wall
from haptic_bus.analysis.loop import WallLoop
from tests.energy_check import DELAYS, MODELS, STEPS, T, bears_out

CANDIDATES = np.geomspace(1e-3, math.pi, 48)  # rad: where the adversarial tone is looked for


def random_designs(seed: int = 22, count: int = 100) -> list[CoupledLoop]:
    """Seeded oblique plane walls on 2-3 axes with different m and b (module docstring)."""
    rng = np.random.default_rng(seed)
    designs = []
    for _ in range(count):
        size = int(rng.choice([2, 3]))
        if rng.random() < 0.5:
            velocities, delays = [str(rng.choice(MODELS))] * size, [float(rng.choice(DELAYS))] * size
        else:
            velocities, delays = [str(v) for v in rng.choice(MODELS, size)], [float(d) for d in rng.choice(DELAYS, size)]
        axes = tuple(WallLoop(float(10 ** rng.uniform(-1, 0.5)), float(10 ** rng.uniform(0, 1.5)), T, 0, 0, delays[i],
                              velocities[i]) for i in range(size))
        normal = rng.choice([-1, 1], size) * rng.uniform(0.3, 1, size)
        designs.append(plane_wall(axes, normal, float(10 ** rng.uniform(2, 4.3)), float(rng.uniform(0, 10))))
    return designs


@pytest.fixture(scope="module")
def judged() -> tuple[list[CoupledLoop], list[CoupledVerdict]]:
    """The 100 designs and the coupled gate's verdict on each."""
    designs = random_designs()
    return designs, [coupled_verdict(loop) for loop in designs]


def test_the_coupled_verdict_agrees_with_the_time_domain_on_100_oblique_walls(judged) -> None:
    designs, verdicts = judged
    outcomes = Counter(v.outcome for v in verdicts)
    assert outcomes == {"passive": 53, "not passive": 37, "unstable": 10}
    assert all(len(v.groups) == 1 for v in verdicts)  # every wall couples all its axes
    machines = [CoupledMachine(loop, *adversarial_input(loop, np.append(CANDIDATES, v.critical_theta)))
                for loop, v in zip(designs, verdicts)]
    runs = simulate_energies(machines, STEPS)
    agree = [bears_out(machine, float(runs.lowest[k]), float(runs.roundoff[k]), verdict.passive)
             for k, (verdict, machine) in enumerate(zip(verdicts, machines))]
    disagreeing = [(k, verdicts[k].outcome, verdicts[k].margin) for k, ok in enumerate(agree) if not ok]
    assert disagreeing == []
    assert sum(agree) == 100


def test_passive_designs_stay_passive_for_tones_in_random_directions(judged) -> None:
    """Beyond the worst tone: two random directions at random frequencies on each passive design."""
    rng = np.random.default_rng(5)
    loops = [loop for loop, verdict in zip(*judged) if verdict.passive] * 2
    machines = [CoupledMachine(loop, float(rng.uniform(0.01, 3.1)), rng.normal(size=loop.size) + 1j * rng.normal(size=loop.size))
                for loop in loops]
    runs = simulate_energies(machines, STEPS)
    assert len(machines) == 106 and np.all(runs.lowest >= -runs.roundoff)
