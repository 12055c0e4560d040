"""Scenes compile to the same force as summing every object, and the gate judges what acts at once."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.control.gate import GatePolicy, PassivityGate
from haptic_bus.control.scene import Detent, Slot, Wall, compile_scene
from haptic_bus.errors import ParameterError, Refusal

SEED_IDEAL = DeviceLoop(m=0.5, b=0.1, T=1e-3, delay=0)
SEED_CIA402 = DeviceLoop(m=0.5, b=0.1, T=1e-3, delay=1)


def brute_force(objects, x: float, v: float) -> float:
    """The wall force by visiting every object (what the compiled scene must equal)."""
    total = 0.0
    for obj in objects:
        for start, end, K, anchor, B in obj.pieces():
            if start <= x < end:
                total += K * (x - anchor) + B * v
    return total


positions = st.floats(-0.1, 0.1)
objects = st.lists(
    st.one_of(
        st.builds(Wall, name=st.just(""), position=positions, normal=st.sampled_from([-1, 1]),
                  stiffness=st.floats(0, 5e3), damping=st.floats(0, 50)),
        st.builds(Detent, name=st.just(""), center=positions, reach=st.floats(1e-4, 0.05),
                  stiffness=st.floats(0, 5e3), damping=st.floats(0, 50)),
        st.builds(lambda lo, w, K, B: Slot("", lo, lo + w, K, B), positions, st.floats(1e-3, 0.1),
                  st.floats(0, 5e3), st.floats(0, 50)),
    ),
    min_size=1, max_size=12,
).map(lambda objs: [type(o)(**{**o.__dict__, "name": f"o{i}"}) for i, o in enumerate(objs)])


@settings(deadline=None)
@given(objs=objects, x=st.floats(-0.2, 0.2), v=st.floats(-1, 1))
def test_compiled_force_equals_the_sum_over_every_object(objs, x: float, v: float) -> None:
    scene = compile_scene(objs)
    expected = brute_force(objs, x, v)
    # fsum per interval vs a running sum here: both within a few ulps of the largest term
    scale = sum(abs(o.stiffness) * 0.3 + abs(o.damping) for o in objs)
    assert scene.force(x, v) == pytest.approx(expected, abs=1e-12 * max(scale, 1.0))


def test_wall_acts_only_while_penetrating() -> None:
    floor = compile_scene([Wall("floor", 0.01, -1, 200.0, 100.0)])
    assert floor.force(0.0099, 0.5) == 0.0
    assert floor.force(0.011, 0.0) == pytest.approx(200.0 * 0.001)
    assert floor.force(0.011, -0.2) == pytest.approx(0.2 - 20.0)
    ceiling = compile_scene([Wall("ceiling", 0.0, 1, 300.0, 0.0)])
    assert ceiling.force(-0.002, 0.0) == pytest.approx(-0.6) and ceiling.force(0.001, 0.0) == 0.0


def test_far_objects_cost_nothing_per_cycle() -> None:
    many = compile_scene([Detent(f"d{i}", i * 0.01, 0.004, 300.0, 1.0) for i in range(1000)])
    # one bisect over the break points: 2 per detent, log2(2000) < 11 comparisons
    assert len(many.breaks) == 2000
    assert many.force(3.0021, 0.0) == pytest.approx(300.0 * 0.0021)
    assert many.force(3.005, 1.0) == 0.0


def test_overlapping_objects_add_and_the_gate_judges_the_sum() -> None:
    scene = compile_scene([Wall("a", 0.0, -1, 150.0, 60.0), Wall("b", 0.001, -1, 150.0, 60.0)])
    contacts = scene.contacts()
    assert contacts[(300.0, 120.0)] == ("a", "b")
    gate = PassivityGate(SEED_IDEAL)
    decision = gate.judge(scene)
    assert decision.accepted and {(w.K, w.B) for w in decision.walls} == {(150.0, 60.0), (300.0, 120.0)}


def test_gate_refuses_the_seed_wall_with_one_sample_of_delay_and_says_why() -> None:
    scene = compile_scene([Wall("floor", 0.0, -1, 200.0, 100.0)])
    assert PassivityGate(SEED_IDEAL).admit(scene).accepted
    with pytest.raises(Refusal) as info:
        PassivityGate(SEED_CIA402).admit(scene)
    message = str(info.value)
    assert "floor" in message and "delay D = 1 samples, velocity point" in message and "margin -84.09 N s/m" in message
    assert "allowed: margin >= 0" in message
    # the passive intervals, not only the largest value: at K = 200 no B is passive with one sample
    assert "passive B at this K: none" in message and "passive K at this B: none" in message


def test_safety_margin_and_strict_bandwidth_policy() -> None:
    scene = compile_scene([Wall("floor", 0.0, -1, 200.0, 100.0)])
    margin = PassivityGate(SEED_IDEAL).judge(scene).worst_margin
    assert margin == pytest.approx(0.0998139, rel=1e-5)
    assert not PassivityGate(SEED_IDEAL, GatePolicy(safety_margin=0.2)).judge(scene).accepted
    soft = compile_scene([Wall("soft", 0.0, -1, 200.0, 1.0)])  # alpha = 5 < 6
    assert PassivityGate(SEED_IDEAL).judge(soft).warnings
    assert not PassivityGate(SEED_IDEAL, GatePolicy(bandwidth="strict")).judge(soft).accepted


@pytest.mark.parametrize("build,field", [
    (lambda: Wall("w", 0.0, 0, 1.0, 1.0), "normal"),
    (lambda: Wall("w", 0.0, True, 1.0, 1.0), "normal"),
    (lambda: Wall("w", math.nan, -1, 1.0, 1.0), "position"),
    (lambda: Wall("w", 0.0, -1, -1.0, 1.0), "stiffness"),
    (lambda: Slot("s", 0.1, 0.0, 1.0, 1.0), "high"),
    (lambda: Detent("d", 0.0, 0.0, 1.0, 1.0), "reach"),
    (lambda: compile_scene([Wall("w", 0, -1, 1, 1), Wall("w", 1, -1, 1, 1)]), "name"),
    (lambda: GatePolicy(safety_margin=-1.0), "safety_margin"),
    (lambda: GatePolicy(bandwidth="sometimes"), "bandwidth"),
])
def test_bad_scene_input_names_the_field(build, field: str) -> None:
    with pytest.raises(ParameterError) as info:
        build()
    assert info.value.name == field and "allowed" in str(info.value)


def test_a_contact_wall_names_every_object_that_makes_it() -> None:
    detents = [Detent(name, center, 0.002, 300.0, 2.0) for name, center in (("left", -0.01), ("home", 0.0), ("right", 0.01))]
    assert compile_scene(detents).contacts() == {(300.0, 2.0): ("home", "left", "right")}


# --------------------------------------------------------------------------- start ramp and derate

END_STEP = 1e-3  # each interval end inside (0, 1) is also sampled this far on either side of it


def _sampled_scales(intervals: tuple[tuple[float, float], ...], n: int = 101) -> list[float]:
    """``n`` scales spread over [0, 1], and each interval end inside (0, 1) bracketed at +-:data:`END_STEP`."""
    ends = [end for interval in intervals for end in interval if END_STEP < end < 1.0 - END_STEP]
    return sorted([i / (n - 1) for i in range(n)] + [end + side * END_STEP for end in ends for side in (-1, 1)])


@pytest.mark.parametrize("device, K, B", [
    (SEED_IDEAL, 200.0, 100.0),
    (DeviceLoop(0.5, 0.1, 1e-3, 2), 56.23, 0.03),
    (DeviceLoop(0.5, 2.0, 1e-3, 1), 3000.0, 1.0),
    (DeviceLoop(0.5, 2.0, 1e-3, 1, "average"), 3000.0, 1.0),
    (DeviceLoop(0.5, 0.1, 1e-3, 0.3), 100.0, 0.05),
    (DeviceLoop(0.37, 2.9, 1e-3, 1, "lowpass:0.0005"), 2000.0, 1.5),
])
def test_the_passive_scales_of_a_wall_agree_with_the_verdict_at_every_sampled_scale(device, K, B):
    """The exact scale intervals against the exact verdict at 101 scales and 1e-3 either side of every
    interval end: no sampled scale disagrees (1e-9 slack at the interval ends, far below 1e-3).  Each of
    these walls is passive on one interval from 0 (to 1, 0.776 or 0.568): the 101 scales check its
    inside and outside (401 did, four times the CPU: 1.6 ms a verdict), the brackets its end closer
    than 1/400 did."""
    from haptic_bus.analysis.criterion import exact_verdict

    scene = compile_scene([Wall("w", 0.0, -1, K, B)])
    intervals = PassivityGate(device).passive_scales(scene)
    scales = _sampled_scales(intervals)
    sampled = [exact_verdict(device.wall(s * K, s * B)).passive for s in scales]
    inside = [any(lo - 1e-9 <= s <= hi + 1e-9 for lo, hi in intervals) for s in scales]
    assert inside == sampled


def test_a_ramp_is_proven_only_when_every_scaled_wall_is_passive() -> None:
    assert PassivityGate(SEED_IDEAL).proves_ramp(compile_scene([Wall("floor", 0.0, -1, 200.0, 100.0)])).proven
    device = DeviceLoop(0.5, 2.0, 1e-3, 1)
    scene = compile_scene([Wall("stop", 0.0, -1, 3000.0, 1.0)])
    proof = PassivityGate(device).proves_ramp(scene)
    # the end point is active too here, but even a passive end point would not do: what counts
    # is the whole way, and the reason names the passive part of it
    assert not proof.proven and "stop scaled by s is passive only for s in [0, 0.7759]" in proof.reason


def test_the_scales_of_overlapping_walls_intersect() -> None:
    device = DeviceLoop(0.5, 2.0, 1e-3, 1)
    scene = compile_scene([Wall("a", 0.0, -1, 2000.0, 1.0), Slot("b", -0.01, 0.01, 1000.0, 0.0)])
    gate = PassivityGate(device)
    common = gate.passive_scales(scene)
    each = [gate.passive_scales(compile_scene([Wall("w", 0.0, -1, K, B)])) for K, B in scene.contacts()]
    for s in (i / 200 for i in range(201)):
        expected = all(any(lo <= s <= hi for lo, hi in intervals) for intervals in each)
        assert any(lo <= s <= hi for lo, hi in common) == expected


def test_derate_serves_an_observed_fractional_delay_with_the_next_prepared_one() -> None:
    from haptic_bus.app.derate_table import DERATE_EXTRA_DELAYS, DerateTable

    device = DeviceLoop(1.0, 20.0, 1e-3, 1, "average")
    scene = compile_scene([Wall("stop", 0.0, -1, 16500.0, 7.0)])
    gate = PassivityGate(device, GatePolicy(safety_margin=1.0))
    gate.admit(scene)
    derate = DerateTable(gate, scene)
    served = derate(scene, 1.3)  # between the prepared 1.25 and 1.5: served by 1.5
    assert served is not None
    judge, scaled, decision = served
    assert judge.device.delay == 1.5 and decision.accepted and decision.worst_margin >= 1.0
    (K, B), = scaled.contacts()
    assert 0 < K / 16500.0 < 1.0 and K / 16500.0 == pytest.approx(B / 7.0, rel=1e-12)
    # the largest such scale: a little more and the gate at D = 1.5 refuses it
    assert not judge.passes(scene.scaled(K / 16500.0 * (1 + 1e-6)))
    assert derate(scene, 1.0 + max(DERATE_EXTRA_DELAYS) + 0.01) is None
