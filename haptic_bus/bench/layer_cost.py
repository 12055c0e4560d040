"""What the passivity layer costs: how much of the wall force it takes away, nominal and bad timing.

Every shipped profile's scene and operator, in virtual time on the lock-step bus (exact and
repeatable), twice: under nominal timing, and under the seeded adversarial timing of
:func:`~haptic_bus.control.clock.adversarial_starts` (stalls of 2-20 ms at 1 % of cycles, 5 %
late cycles, jitter) that the simulated drive lives too.  For each layer (``off``, ``guard``,
``bound`` with the default safety settings' hold: the RPDO deadline plus a period):

* ``lowered``: the share of cycles whose target the layer lowered;
* ``gain``: the least-squares share of the asked wall force that reached the handle over the
  cycles in contact, ``sum(applied * asked) / sum(asked^2)`` (1: untouched; what the operator
  feels as the wall's stiffness and damping scaled);
* ``removed_max``: the largest force the layer took off one target, N;
* ``least_energy``: the least port energy of the run by the simulated drive's exact ledger, J
  (below zero: the wall gave the operator energy).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from drives.safety import DEFAULT_SAFETY
from haptic_bus.app.profiles import load_profile, shipped_profiles
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.bench.size import Size
from haptic_bus.control.clock import ScheduledClock, VirtualClock, adversarial_starts
from haptic_bus.control.controller import WallController, encoder_origin
from haptic_bus.control.passivity_layer import LAYER_MODES, LayerPolicy

SEED = 1  # the adversarial schedule's seed


def measure(profile_name: str, layer: str, adversarial: bool, seconds: float) -> dict[str, float]:
    """One run of ``profile_name`` under ``layer``: the figures of the module docstring."""
    profile = load_profile(profile_name)
    period = profile.loop.period
    cycles = round(seconds / period)
    clock: ScheduledClock | VirtualClock
    clock = ScheduledClock(period, adversarial_starts(period, cycles, SEED)) if adversarial else VirtualClock(period)
    hold = DEFAULT_SAFETY.rpdo_deadline_ms(period) / 1000.0 + period
    least = np.inf
    with simulated_canopen(profile, sync_clock=clock.sync_clock() if isinstance(clock, ScheduledClock) else None,
                           substeps=4) as (sim, drive):
        origin = encoder_origin(drive)
        scene = profile.compiled_scene()
        stored = scene.stored_energy(origin)
        controller = WallController(drive, profile.gate(), scene, force_limit=profile.force_limit, clock=clock,
                                    origin=origin, supervisor=None, passivity=LayerPolicy(layer), hold=hold)

        def watch(c: WallController) -> None:
            nonlocal least
            least = min(least, stored + sim.drive.viscous_energy + sim.drive.wall_energy)

        summary = controller.run(cycles, on_cycle=watch)
    data = controller.record.array()
    columns = {name: i for i, name in enumerate(("time_s", "position_m", "velocity_m_per_s", "force_n",
                                                  "torque_permille", "energy_j", "scene_id", "scale", "late",
                                                  "compute_s", "layer_n"))}
    asked = data[:, columns["force_n"]]
    applied = -data[:, columns["torque_permille"]] * drive.scaling.newton_per_permille
    contact = asked != 0.0
    gain = float(np.dot(applied[contact], asked[contact]) / np.dot(asked[contact], asked[contact])) if contact.any() else 1.0
    return {"lowered": summary.layer_interventions / max(summary.cycles, 1), "gain": gain,
            "removed_max": float(np.max(np.abs(data[:, columns["layer_n"]]), initial=0.0)),
            "least_energy": float(least), "cycles": summary.cycles}


def run(size: Size, tick: Callable[[str], None] = lambda _: None, profiles: Sequence[str] | None = None) -> dict[str, Any]:
    """Every shipped profile (smoke: one) x {nominal, adversarial} x every layer, 0.2 / 2 / 10 s each."""
    seconds = size.pick(0.2, 2.0, 10.0)
    rows = []
    for name in profiles or size.pick(["cia402-handle"], sorted(shipped_profiles()), sorted(shipped_profiles())):
        for adversarial in (False, True):
            for layer in LAYER_MODES:
                rows.append({"profile": name, "timing": "adversarial" if adversarial else "nominal", "layer": layer,
                             **measure(name, layer, adversarial, seconds)})
        tick(name)
    return {"seconds": seconds, "seed": SEED, "rows": rows}
