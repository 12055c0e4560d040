"""validate's candidates are ranked by Akaike's criterion, so a candidate with a parameter to spare
does not win by mimicking a simpler one (haptic_bus.validate.departures)."""

from __future__ import annotations

import dataclasses

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.analysis.transmission import Transmission
from haptic_bus.validate import two_mass
from haptic_bus.validate.departures import departures, explains
from haptic_bus.validate.model import Hold, plant_response
from haptic_bus.validate.probe import ProbePlan
from haptic_bus.validate.spectra import Measured

LOOP = DeviceLoop(1.0, 20.0, 1e-3, 1.0, "average")  # the cia402-handle's model
PLAN = ProbePlan.for_loop(LOOP, Hold(157.9, 5.13))  # its probe: 203 tones, 3.9 to 398 Hz
RELATIVE_ERROR = 1e-3  # each frequency's standard error, relative: the measurement's noise


def _measured(truth: np.ndarray, seed: int) -> Measured:
    """``truth`` (m/s per N) with complex Gaussian noise of standard error RELATIVE_ERROR |truth|."""
    rng = np.random.default_rng(seed)
    error = RELATIVE_ERROR * np.abs(truth)
    noise = (rng.standard_normal(truth.size) + 1j * rng.standard_normal(truth.size)) / np.sqrt(2.0)
    return Measured(PLAN.theta, truth + error * noise, error)


def test_a_heavier_handle_is_named_mass_not_a_resonance_that_mimics_it() -> None:
    # a transmission with c = b and k = b^2/m behind a 1.2 kg motor is exactly a rigid 1.2 kg handle,
    # so the resonance fits as well as the mass to within the noise; the simpler candidate is named
    fits = departures(_measured(plant_response(dataclasses.replace(LOOP, m=1.2), PLAN.theta), seed=27), LOOP)
    by_name = {fit.name: fit for fit in fits}
    mass_fit, resonance_fit = by_name["mass and friction"], by_name["resonance"]
    # the mimicry is real: least chi2 alone would not separate them (406 real numbers, chi2 about 203
    # each; a difference of a few units is what one spare parameter gains on noise)
    assert abs(resonance_fit.chi2 - mass_fit.chi2) < 2.0 * (resonance_fit.parameters - mass_fit.parameters)
    assert fits[0].name == "mass and friction"
    mass, friction = mass_fit.findings
    # the fitted values lie within 4 of their standard deviations of the truth (seeded noise)
    assert abs(mass.values["value"] - 1.2) < 4.0 * mass.uncertainty["value"]
    assert abs(friction.values["value"] - 20.0) < 4.0 * friction.uncertainty["value"]


def test_a_true_transmission_is_still_named_a_resonance() -> None:
    coupling = Transmission(20000.0, 2.0, 0.3)  # the belt: 46.8 Hz, damping ratio 0.023
    fits = departures(_measured(two_mass.response(LOOP, coupling, PLAN.theta), seed=28), LOOP)
    assert fits[0].name == "resonance"
    finding = fits[0].findings[0]
    frequency, damping = two_mass.mode(LOOP, coupling)
    # within 4 standard deviations of the hidden truth
    assert abs(finding.values["frequency"] - frequency) < 4.0 * finding.uncertainty["frequency"]
    assert abs(finding.values["damping"] - damping) < 4.0 * finding.uncertainty["damping"]
    # and the simpler candidates are far behind: the rigid plant cannot show a resonance
    assert fits[1].criterion - fits[0].criterion > 1e3


def test_a_departure_no_candidate_fits_is_not_explained_and_a_known_one_is() -> None:
    """The belt is explained within the noise (chi2 about its 406 - 6 degrees of freedom); a plant with a
    10 % ripple across frequency, which no candidate has, leaves a chi2 far beyond the chi-square
    distribution's 99.9th percentile (about 494): told so, not named after the closest candidate."""
    numbers = 2 * PLAN.bins.size
    belt = departures(_measured(two_mass.response(LOOP, Transmission(20000.0, 2.0, 0.3), PLAN.theta), seed=29), LOOP)
    assert explains(belt[0], numbers)
    rippled = plant_response(LOOP, PLAN.theta) * (1.0 + 0.1 * np.sin(40.0 * PLAN.theta))
    odd = departures(_measured(rippled, seed=30), LOOP)
    assert not explains(odd[0], numbers) and odd[0].chi2 > 10 * numbers


def test_a_value_the_data_do_not_determine_has_no_uncertainty_rather_than_zero() -> None:
    # a heavier rigid handle seen through the resonance candidate: the fit's pair is over-damped, its
    # damping ratio is 1 for any nearby parameters (zero gradient), so its spread is undetermined, not
    # +- 0 (the breaker's report); the parameters the data do see keep a finite, positive spread
    truth = plant_response(dataclasses.replace(LOOP, m=1.2), PLAN.theta)
    (resonance,) = next(fit for fit in departures(_measured(truth, seed=3), LOOP) if fit.name == "resonance").findings
    assert resonance.values["damping"] == 1.0 and resonance.uncertainty["damping"] is None
    assert resonance.to_dict()["uncertainty"]["damping"] is None  # JSON null, never a made-up 0
    assert "damping 1 (undetermined)" in resonance.describe()
    determined = [sigma for name, sigma in resonance.uncertainty.items() if name != "damping"]
    assert all(sigma is not None and 0.0 < sigma < np.inf for sigma in determined)


def test_a_rigid_handle_leaves_the_resonance_stiffness_at_its_bound_undetermined() -> None:
    # no transmission at all: the candidate's stiffness runs to the bound of its range, where the
    # curvature says nothing of it; the frequency and damping it sets are undetermined with it
    (resonance,) = next(fit for fit in departures(_measured(plant_response(LOOP, PLAN.theta), seed=3), LOOP)
                        if fit.name == "resonance").findings
    assert all(resonance.uncertainty[name] is None for name in ("stiffness", "frequency", "damping"))
    assert "stiffness" in resonance.describe() and "N/m (undetermined)" in resonance.describe()
