"""The check report: velocity model, real delay, passive intervals, the lossless outcome, out-of-band exposure."""

from __future__ import annotations

import json

from haptic_bus.analysis.check import check_loop, check_passivity, format_check
from haptic_bus.analysis.loop import WallLoop

OLD_KEYS = {"passive", "criterion", "margin", "margin_units", "critical_theta", "stable", "spectral_radius",
            "max_stiffness", "max_damping", "limits_relative_tolerance", "parameters", "closed_loop_poles",
            "seed_t_zw", "closed_forms", "bandwidth_rule"}


def test_the_report_keeps_every_old_key_and_adds_the_new_ones() -> None:
    report = check_passivity(0.5, 0.1, 1e-3, 20.0, 0.05, delay=1.25, velocity="lowpass:0.0005", out_of_band=True)
    data = json.loads(json.dumps(report.to_dict()))
    assert set(data) >= OLD_KEYS
    assert data["parameters"]["delay"] == 1.25 and data["parameters"]["velocity"] == "lowpass:0.0005"
    assert data["outcome"] in ("passive", "not passive", "unstable", "lossless") and data["lossless"] is False
    assert data["max_stiffness"] == data["stiffness_passive"]["largest"]
    assert data["max_damping"] == data["damping_passive"]["largest"]
    band = data["out_of_band"]
    assert band["pair"]["power"] <= 0 and len(band["pair"]["frequencies_hz"]) == 2 and band["harmonics"]["harmonics"] == 16


def test_passive_intervals_that_do_not_start_at_zero_are_reported_and_printed() -> None:
    report = check_loop(WallLoop(0.5, 0.1, 1e-3, 100.0, 0.03, 1))
    low, high = report.damping_set.intervals[0]
    assert 0 < low < high == report.max_damping and report.damping_set.ends() == ((True, True),)
    text = format_check(report)
    assert f"passive B at this K: [{low:.9g}, {high:.9g}] N s/m" in text
    assert "velocity=point" in text and "delay=1 samples" in text and "out of band" in text


def test_an_unstable_loop_has_no_out_of_band_figure_and_says_so() -> None:
    report = check_passivity(0.5, 0.1, 1e-3, 1e7, 0.0, out_of_band=True)
    assert not report.stable and report.out_of_band is None and report.outcome == "unstable"
    assert report.to_dict()["out_of_band"] is None
    assert "not applicable, the loop is not stable" in format_check(report)


def test_the_library_check_computes_the_exposure_only_when_asked() -> None:
    """``check_passivity`` (the API) leaves the out-of-band search out unless asked; ``check_loop``
    (what ``haptic-bus check`` runs) asks by default."""
    quiet = check_passivity(0.5, 0.1, 1e-3, 200.0, 100.0)
    assert quiet.out_of_band is None and not quiet.out_of_band_asked
    assert "out of band (above Nyquist): not asked" in format_check(quiet)
    assert check_loop(WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0)).out_of_band is not None


def test_eq23_applies_only_to_the_seeds_own_loop() -> None:
    assert check_passivity(0.5, 0.1, 1e-3, 200.0, 100.0).velocity_sampling_eq23.applies
    assert not check_passivity(0.5, 0.1, 1e-3, 200.0, 100.0, velocity="average").velocity_sampling_eq23.applies
    assert not check_passivity(0.5, 0.1, 1e-3, 200.0, 100.0, delay=0.25).velocity_sampling_eq23.applies


def test_the_lossless_mass_is_named_in_the_text() -> None:
    text = format_check(check_passivity(0.5, 0.0, 1e-3, 0.0, 0.0))
    assert "passive (lossless)" in text and "marginally stable" in text and "UNSTABLE" not in text


def test_the_out_of_band_line_says_what_its_sign_means_for_this_loop() -> None:
    """The worst force's line said "(< 0: the operator can take energy out)" after a positive figure too
    (cia402-handle's wall: +6.167e-12 W per N^2, break18); the words follow the sign."""
    takes_out = check_loop(WallLoop(0.5, 0.1, 1e-3, 200.0, 1.0, 1.5))
    keeps = check_loop(WallLoop(1.0, 20.0, 1e-3, 1500.0, 10.0, 1, "average"))
    assert takes_out.out_of_band is not None and keeps.out_of_band is not None
    assert takes_out.out_of_band.harmonics.power < 0 < keeps.out_of_band.harmonics.power
    assert "W per N^2 (< 0: the operator can take energy out)" in format_check(takes_out)
    assert "W per N^2 (>= 0: none of these forces takes energy out)" in format_check(keeps)
