"""Pre-flight's refusal of a wall not passive at the measured delay without a layer names a fix
that works: a softer wall or a shorter ``T`` this machine holds, never a longer ``T``.

stiff-wall (K = 16500 N/m, B = 7 N s/m, margin 1.084 N s/m at D = 1 against the 1 N s/m its gate
asks) with ``[passivity] layer = "off"``: a machine adding 30 us each cycle is judged at
D = 1.03 samples, where the gate refuses it.  The same wall passes at T = 0.75 ms (the shortest
this timing holds: busy 0.53 ms, on the 0.25 ms grid) with those 30 us (D = 1.04), and fails at
T = 1.25 ms (D = 1.024): a longer ``T`` adds seconds of delay and K T (breaker14: the refusal
said "or a longer T", and stiff-wall at T = 1.2 ms is refused by the gate before any bus).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from haptic_bus.app import preflight
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.profiles.one_axis import Profile
from haptic_bus.control.gate import PassivityGate

T = 1e-3  # s: stiff-wall's period
ADDED = 30e-6  # s: each cycle starts this late after its deadline
EXCHANGE = 0.5e-3  # s: each cycle's exchange with the drive
CYCLES = 500


def _timing() -> preflight.Timing:
    deadlines = np.arange(CYCLES) * T
    return preflight.Timing(T, np.full(CYCLES, ADDED), deadlines + ADDED, np.full(CYCLES, EXCHANGE), 0)


def _stiff_wall() -> Profile:
    profile = load_profile("stiff-wall")
    assert isinstance(profile, Profile)
    return profile


def test_refusal_names_a_shorter_period_the_machine_holds() -> None:
    profile = _stiff_wall()
    gate, scene = profile.gate(), profile.compiled_scene()
    report = preflight.judge(_timing(), gate, scene, "off", watchdog=0.03, deadline_periods=30)
    assert abs(report.observed_delay - 1.03) < 1e-9  # D + 30 us / 1 ms, to rounding
    assert not report.holdable and report.passive_at_observed is False
    assert report.smallest_period is not None and abs(report.smallest_period - 0.75e-3) < 1e-12
    assert "longer T" not in report.reason
    assert report.reason.endswith('a softer wall, or a shorter T: this machine holds T >= 0.75 ms')


def test_the_advice_holds_for_the_gate() -> None:
    profile = _stiff_wall()
    loop, scene = profile.device_loop(), profile.compiled_scene()

    def passes(period: float) -> bool:
        judged = dataclasses.replace(loop, T=period, delay=1.0 + ADDED / period)
        return PassivityGate(judged, profile.gate_policy).passes(scene)

    assert not passes(T)  # the refusal
    assert passes(0.75e-3)  # the shorter T named
    assert not passes(1.25e-3)  # a longer one
