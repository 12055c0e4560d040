"""A profile the simulated drive runs is its truth, [device.transmission] included: the handle the
gate judges is the handle the drive moves (``haptic-bus sim --profile``; before, it ran a rigid one
and a validate against it could not see the profile's own belt)."""

from __future__ import annotations

import pathlib

from haptic_bus.analysis.transmission import Transmission
from haptic_bus.profile.files import shipped_profiles
from sim_drive.profile import load_profile

TABLE = "\n[device.transmission]\nstiffness = 20000.0\ndamping = 2.0\nmotor_mass = 0.3\n\n[loop]"


def test_the_simulated_drive_runs_the_transmission_a_profile_states(tmp_path: pathlib.Path) -> None:
    text = shipped_profiles()["cia402-handle"].read_text()
    assert text.count("\n[loop]") == 1
    path = tmp_path / "belt.toml"
    path.write_text(text.replace("\n[loop]", TABLE))
    parameters = load_profile(path).parameters
    assert parameters.coupling == Transmission(20000.0, 2.0, 0.3)
    assert (parameters.mass, parameters.friction) == (1.0, 20.0)  # the handle's, as the profile states
    assert load_profile("cia402-handle").parameters.coupling is None  # no table: a rigid handle
