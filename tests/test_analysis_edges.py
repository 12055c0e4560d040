"""Issue 19's edges: no friction, the lossless oscillator, a capped limit -- the printed passive
intervals agree with the verdict, ends open or closed as they are.

Closed forms for the frictionless point-velocity loop without delay (``b = 0``): ``Re Z(pi) = 0``
for every wall, so every stable wall is passive with margin exactly 0; the flip (a pole at
``z = -1``) is ``K T/2 + B = 2m/T`` (eq. 23's ``b / tanh(bT/2m)`` as ``b -> 0``), an open end
(the wall there has a pole on the circle).  Tolerances: the flip is solved in closed form from
the characteristic function (a few ulps: asserted 1e-12 relative); "just inside/outside" is
1e-6 relative, far beyond both round-offs.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from haptic_bus.analysis.check import check_loop
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.limits import passive_limits
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import closed_loop_poles, stability
from haptic_bus.app.cli import main

M, T = 0.5, 1e-3
FLIP = 2 * M / T  # K T/2 + B at the flip without friction: 1000 N s/m


def _check(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    status = main(["check", "--mass", "0.5", "--friction", "0", "--period", "1e-3", *args])
    return status, capsys.readouterr().out


def test_a_frictionless_damper_is_passive_with_margin_zero_up_to_the_flip(capsys: pytest.CaptureFixture[str]) -> None:
    """The issue printed "passive B at this K: [0, 0]"; every stable wall is passive here."""
    loop = WallLoop(M, 0.0, T, 0.0, 500.0)
    verdict = exact_verdict(loop)
    assert verdict.passive and verdict.margin == 0.0
    stiffness, damping = passive_limits(loop)
    assert stiffness.intervals[0][0] == 0.0 and stiffness.intervals[0][1] == pytest.approx(2 * (FLIP - 500) / T, rel=1e-12)
    assert stiffness.ends() == ((True, False),) and len(stiffness.intervals) == 1
    assert damping.intervals[0][1] == pytest.approx(FLIP, rel=1e-12) and damping.ends() == ((True, False),)
    for K, passive in ((1e6 * (1 - 1e-6), True), (1e6 * (1 + 1e-6), False), (1.0, True)):
        assert exact_verdict(loop.with_wall(K, 500.0)).passive is passive
    status, out = _check(capsys, "--stiffness", "0", "--damping", "500")
    assert status == 0 and "margin +0 N s/m" in out
    assert "passive K at this B: [0, 1000000) N/m; passive B at this K: [0, 1000) N s/m" in out


def test_a_frictionless_spring_with_a_little_damping_has_an_open_interval(capsys: pytest.CaptureFixture[str]) -> None:
    """The issue printed "none; none"; the truth is B in (0, 999.95): B = 0 is the lossless oscillator."""
    loop = WallLoop(M, 0.0, T, 100.0, 1.0)
    assert exact_verdict(loop).passive
    stiffness, damping = passive_limits(loop)
    assert damping.intervals == ((0.0, pytest.approx(FLIP - 100 * T / 2, rel=1e-12)),)
    assert damping.ends() == ((False, False),)
    assert stiffness.intervals[0][1] == pytest.approx(2 * (FLIP - 1.0) / T, rel=1e-12) and stiffness.ends() == ((True, False),)
    assert not exact_verdict(loop.with_wall(100.0, 0.0)).passive and exact_verdict(loop.with_wall(100.0, 1e-9)).passive
    status, out = _check(capsys, "--stiffness", "100", "--damping", "1")
    assert status == 0 and "passive B at this K: (0, 999.95) N s/m" in out


def test_an_unstable_frictionless_delayed_spring_does_not_print_every_stiffness(capsys: pytest.CaptureFixture[str]) -> None:
    """The issue printed "passive K: [0, 1e+15]" beside UNSTABLE; only K = 0 (the free mass) is passive."""
    loop = WallLoop(M, 0.0, T, 10.0, 0.0, 1)
    verdict = exact_verdict(loop)
    assert not verdict.passive and not verdict.stable
    stiffness, damping = passive_limits(loop)
    assert stiffness.intervals == ((0.0, 0.0),) and damping.intervals == ()
    status, out = _check(capsys, "--stiffness", "10", "--damping", "0", "--delay", "1")
    assert status == 1 and "UNSTABLE" in out and "1e+15" not in out
    assert "passive K at this B: only 0 N/m; passive B at this K: none" in out


def test_a_frictionless_delayed_averaging_damper_is_passive_only_at_zero(capsys: pytest.CaptureFixture[str]) -> None:
    """The issue printed "passive B: [0, 1916.25]" beside margin -0.8178; only B = 0 is passive."""
    loop = WallLoop(M, 0.0, T, 0.0, 1.0, 1, "average")
    verdict = exact_verdict(loop)
    assert verdict.stable and not verdict.passive and verdict.margin == pytest.approx(-0.8178, abs=1e-4)
    stiffness, damping = passive_limits(loop)
    assert damping.intervals == ((0.0, 0.0),) and stiffness.intervals == ()
    for B in (1e-9, 1e-3, 100.0, 1916.0):
        assert not exact_verdict(loop.with_wall(0.0, B)).passive
    status, out = _check(capsys, "--stiffness", "0", "--damping", "1", "--delay", "1", "--velocity", "average")
    assert status == 1 and "passive K at this B: none; passive B at this K: only 0 N s/m" in out


@pytest.mark.parametrize("K", [1.0, 100.0, 1.9e6])
def test_a_spring_on_a_frictionless_handle_is_a_lossless_oscillator(K: float, capsys: pytest.CaptureFixture[str]) -> None:
    """b = B = 0, no delay: the poles lie on the unit circle (product 1); not passive by the strict rule."""
    loop = WallLoop(M, 0.0, T, K, 0.0)
    poles = closed_loop_poles(loop)
    assert poles.size == 2 and np.abs(poles) == pytest.approx([1.0, 1.0], abs=1e-15)
    assert abs(poles[0] * poles[1]) == pytest.approx(1.0, abs=1e-15)
    assert stability(loop).state == "marginal"
    verdict = exact_verdict(loop)
    assert verdict.outcome == "lossless oscillator" and not verdict.passive and verdict.margin < 0
    assert verdict.oscillator and not verdict.stable
    report = check_loop(loop)
    assert report.outcome == "lossless oscillator" and report.out_of_band is None
    assert report.stiffness_set.intervals == ((0.0, 0.0),)  # only the free mass
    status, out = _check(capsys, "--stiffness", f"{K!r}", "--damping", "0")
    assert status == 1 and "lossless oscillator" in out and "UNSTABLE" not in out


def test_past_four_the_frictionless_spring_is_unstable_not_an_oscillator() -> None:
    """K T^2/m > 4: real poles with product 1, one outside the circle."""
    verdict = exact_verdict(WallLoop(M, 0.0, T, 4.1 * M / T**2, 0.0))
    assert verdict.outcome == "unstable" and verdict.spectral_radius > 1.0


def test_a_capped_limit_says_it_is_only_the_ceiling(capsys: pytest.CaptureFixture[str]) -> None:
    """The issue printed 1e15 where 2e18 holds: the largest passive K is at least the input ceiling."""
    report = check_loop(WallLoop(1e9, 1e9, 1e-9, 0.0, 0.0, 0, "average"))
    assert report.stiffness_set.capped and report.max_stiffness == 1e15 and not report.damping_set.capped
    assert report.to_dict()["stiffness_passive"]["largest_at_least"] is True
    status = main(["check", "--mass", "1e9", "--friction", "1e9", "--period", "1e-9", "--stiffness", "0",
                   "--damping", "0", "--velocity", "average"])
    out = capsys.readouterr().out
    assert status == 0 and "largest at least 1e+15 (the input ceiling)" in out


def test_the_json_carries_open_and_closed_ends(capsys: pytest.CaptureFixture[str]) -> None:
    status, out = _check(capsys, "--stiffness", "100", "--damping", "1", "--json")
    data = json.loads(out)
    assert status == 0 and data["damping_passive"]["closed"] == [[False, False]]
    assert data["stiffness_passive"]["closed"] == [[True, False]] and data["stiffness_passive"]["largest_at_least"] is False


def test_the_issue_corner_loop_is_passive_on_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    """m 8.1e7 kg, T 2.1 ns: the issue printed UNSTABLE, margin -0.0444; it is stable and passive."""
    status = main(["check", "--mass", "81111842.28316566", "--friction", "0.09841793101174633", "--period",
                   "2.086875209114912e-09", "--stiffness", "23970.471528040052", "--damping", "0.027791958297842794",
                   "--delay", "0.5", "--velocity", "window:2.501302623119371e-10", "--json"])
    data = json.loads(capsys.readouterr().out)
    assert status == 0 and data["passive"] and data["stable"] and data["margin"] == pytest.approx(0.07916, abs=1e-5)
