"""A profile that states [device.transmission] is the same device wherever it is read.

Written into JSON (run.json's settings, ``profiles show --json``) as its table: it used to stop every
run and validate of such a profile with "Object of type Transmission is not JSON serializable" before
the bus was touched.  And the simulated drive runs it as its truth (``haptic-bus sim --profile``):
before, it ran a rigid handle, and a validate against it could not see the profile's own belt."""

from __future__ import annotations

import json
import pathlib

from haptic_bus.analysis.transmission import Transmission
from haptic_bus.app.profiles import load_profile, profile_to_dict
from sim_drive.profile import read_simulated_device
from tests.run_rig import profile_variant

TABLE = "\n[device.transmission]\nstiffness = 20000.0\ndamping = 2.0\nmotor_mass = 0.3\n\n[loop]"


def _belt(folder: pathlib.Path) -> pathlib.Path:
    """cia402-handle behind the issue's belt (20000 N/m, 2 N s/m, a 0.3 kg motor)."""
    return profile_variant(folder, "cia402-handle", "belt", {"\n[loop]": TABLE})


def test_a_profile_with_a_transmission_is_json_with_its_table(tmp_path: pathlib.Path) -> None:
    document = json.loads(json.dumps(profile_to_dict(load_profile(_belt(tmp_path)))))
    assert document["device"]["transmission"] == {"stiffness": 20000.0, "damping": 2.0, "motor_mass": 0.3}
    assert document["device"]["velocity"] == "average"


def test_the_simulated_drive_runs_the_transmission_a_profile_states(tmp_path: pathlib.Path) -> None:
    parameters = read_simulated_device(_belt(tmp_path)).axes[0].parameters
    assert parameters.coupling == Transmission(20000.0, 2.0, 0.3)
    assert (parameters.mass, parameters.friction) == (1.0, 20.0)  # the handle's, as the profile states
    assert read_simulated_device("cia402-handle").axes[0].parameters.coupling is None  # no table: a rigid handle
