"""validate checks the model the gate judges with: a profile that states [device.transmission] is
predicted with the two-mass plant, not the rigid handle (haptic_bus.validate.model).  Before, validate
of such a profile against a drive that is exactly that profile said "differs: resonance" with the
profile's own stiffness, damping and motor mass."""

from __future__ import annotations

import dataclasses

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.analysis.transmission import Transmission
from haptic_bus.validate import two_mass
from haptic_bus.validate.departures import nominal
from haptic_bus.validate.model import Hold, predict
from haptic_bus.validate.probe import ProbePlan
from haptic_bus.validate.spectra import Measured

RIGID = DeviceLoop(1.0, 20.0, 1e-3, 1.0, "average")  # the cia402-handle's model
BELT = Transmission(20000.0, 2.0, 0.3)  # the belt: 46.8 Hz
STATED = dataclasses.replace(RIGID, transmission=BELT)  # the profile that states it
HOLD = Hold(157.9, 5.13)
PLAN = ProbePlan.for_loop(RIGID, HOLD)  # 203 tones, 3.9 to 398 Hz
RELATIVE_ERROR = 1e-3  # each frequency's standard error, relative


def test_the_prediction_of_a_stated_transmission_is_the_two_mass_loop() -> None:
    plant = two_mass.response(RIGID, BELT, PLAN.theta)
    prediction = predict(STATED, HOLD, PLAN.theta)
    closed = plant / (1.0 + plant * HOLD.response(RIGID.T, PLAN.theta))
    # the same arithmetic on the same plant: equal to round-off (responses of order 1e-4..1e-1 m/s per N)
    np.testing.assert_allclose(prediction.plant, plant, rtol=1e-12)
    np.testing.assert_allclose(prediction.velocity, closed, rtol=1e-9)
    # and it is not the rigid handle's: the resonance moves the response by far more than any tolerance
    rigid = predict(RIGID, HOLD, PLAN.theta)
    assert np.max(np.abs(prediction.velocity / rigid.velocity - 1.0)) > 1.0


def test_a_device_equal_to_the_stated_transmission_leaves_only_noise() -> None:
    rng = np.random.default_rng(27)
    truth = two_mass.response(RIGID, BELT, PLAN.theta)
    error = RELATIVE_ERROR * np.abs(truth)
    noise = (rng.standard_normal(truth.size) + 1j * rng.standard_normal(truth.size)) / np.sqrt(2.0)
    measured = Measured(PLAN.theta, truth + error * noise, error)
    # chi2 of 203 complex residuals of unit variance: mean 203, standard deviation sqrt(203) = 14.2;
    # 6 standard deviations is the bound (seeded)
    assert abs(nominal(measured, STATED).chi2 - 203.0) < 6.0 * np.sqrt(203.0)
    # the rigid model of the same handle is off by the resonance: millions
    assert nominal(measured, RIGID).chi2 > 1e6
