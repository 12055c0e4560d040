"""validate's "cannot tell" when the handle leaves the travel names when it left from the probe's start,
or says it left in the quiet hold before the probe (a steady 3 N past 10 mm 0.138 s after the first
cycle was called "0.138 s into the probe", the probe beginning only at 0.5 s)."""

from __future__ import annotations

from haptic_bus.app.profiles import one_axis_only, read_profile
from haptic_bus.app.validate_run import left_travel_said
from haptic_bus.validate.probe import AmplitudeRule, Probe, ProbePlan, gentle_hold

TRAVEL = 0.01  # m either side


def _probe() -> Probe:
    """cia402-handle's probe (T = 1 ms: a quiet hold of 500 cycles), a 0.5 N peak whatever the noise."""
    profile = one_axis_only(read_profile("cia402-handle"), "validate")
    loop = profile.device_loop()
    plan = ProbePlan.for_loop(loop, gentle_hold(loop, profile.gate()))
    return Probe(plan, AmplitudeRule(0.0, 0.0, 0.0, 0.5, 0.5), TRAVEL, lambda: None)


def _left_at(probe: Probe, cycle: int) -> str:
    """Step ``probe`` at rest (0 m) until ``cycle``, then 10.5 mm out; what validate says of it."""
    for _ in range(cycle):
        probe.step(0.0, 0.0)
    probe.step(0.0105, 0.0)
    assert probe.left == (cycle, 0.0105)
    return left_travel_said(probe)


def test_left_in_the_quiet_hold_is_not_called_into_the_probe() -> None:
    probe = _probe()
    assert probe.plan.quiet == 500  # 0.5 s at T = 1 ms
    said = _left_at(probe, 138)
    assert "0.138 s into the quiet hold, before the probe began" in said
    assert "into the probe" not in said
    assert "+10.5 mm" in said  # four digits: 10.5 mm beyond 10 mm was '+10 mm' at three


def test_left_during_the_probe_counts_from_its_start() -> None:
    said = _left_at(_probe(), 2130)  # 2.13 s after the first cycle: 1.63 s after the quiet hold
    assert "1.63 s into the probe" in said
    assert "quiet hold" not in said
