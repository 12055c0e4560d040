"""What the passivity layer costs: how much of the wall force it takes away, nominal and bad timing.

Every shipped profile's scene and operator, in virtual time on the lock-step bus (exact and
repeatable), twice: under nominal timing, and under the seeded adversarial timing of
:func:`~haptic_bus.control.clock.adversarial_starts` (stalls of 2-20 ms at 1 % of cycles, 5 %
late cycles, jitter) that the simulated drive lives too.  For each layer (``off``, ``guard``,
``bound`` with the default safety settings' hold: the RPDO deadline plus a period):

* ``lowered``: the share of cycles whose target the layer lowered;
* ``reached``: the share of the force asked of the drive (the wall force after the force limit,
  ``force_n``) that the target sent carried (``torque_permille``, after the layer), over the
  cycles in contact: ``sum_k min(|asked_k|, max(0, applied_k sign(asked_k))) / sum_k |asked_k|``,
  in [0, 1] by construction (a target rounded above its asked force counts as the asked force, one
  rounded below as what it carried); None when no cycle was in contact;
* ``removed_max``: the largest force the layer took off one target (``layer_n``), N; at most the
  profile's force limit, since the layer only lowers a target the drive's clamp holds within it;
* ``least_energy``: the least port energy of the run by the simulated drive's exact ledger, J
  (below zero: the wall gave the operator energy).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from drives.safety import DEFAULT_SAFETY
from haptic_bus.app.profiles import load_profile, one_axis_only, shipped_profiles
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.bench.size import Size
from haptic_bus.control.clock import ScheduledClock, VirtualClock, adversarial_starts
from haptic_bus.control.controller import WallController
from haptic_bus.control.joints import encoder_origin
from haptic_bus.control.passivity_layer import LAYER_MODES, LayerPolicy

SEED = 1  # the adversarial schedule's seed


def measure(profile_name: str, layer: str, adversarial: bool, seconds: float) -> dict[str, float | None]:
    """One run of ``profile_name`` under ``layer``: the figures of the module docstring."""
    profile = one_axis_only(load_profile(profile_name), "bench")
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
    record = controller.record
    asked = record.column("force_n")
    applied = -record.column("torque_permille") * drive.scaling.newton_per_permille
    return {"lowered": summary.layer_interventions / max(summary.cycles, 1), "reached": reached_share(asked, applied),
            "removed_max": float(np.max(np.abs(record.column("layer_n")), initial=0.0)),
            "least_energy": float(least), "cycles": summary.cycles}


def reached_share(asked: np.ndarray, applied: np.ndarray) -> float | None:
    """The share of the ``asked`` forces (N, per cycle) that the ``applied`` ones (N) carried over the
    cycles in contact (asked non-zero), in [0, 1]: each cycle counts what went out in the asked
    direction, at most what was asked; None without contact."""
    contact = asked != 0.0
    if not contact.any():
        return None
    magnitude = np.abs(asked[contact])
    carried = np.clip(applied[contact] * np.sign(asked[contact]), 0.0, magnitude)
    return float(np.sum(carried) / np.sum(magnitude))


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
