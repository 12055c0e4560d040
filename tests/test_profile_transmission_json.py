"""A profile that states [device.transmission] is written into JSON (run.json's settings,
`profiles show --json`) as its table; it used to stop every run and validate of such a profile with
"Object of type Transmission is not JSON serializable" before the bus was touched."""

from __future__ import annotations

import json
import pathlib

from haptic_bus.app.profiles import load_profile, profile_to_dict
from haptic_bus.profile.files import shipped_profiles

TABLE = "\n[device.transmission]\nstiffness = 20000.0\ndamping = 2.0\nmotor_mass = 0.3\n\n[loop]"


def test_a_profile_with_a_transmission_is_json_with_its_table(tmp_path: pathlib.Path) -> None:
    text = shipped_profiles()["cia402-handle"].read_text()
    assert text.count("\n[loop]") == 1
    path = tmp_path / "belt.toml"
    path.write_text(text.replace("\n[loop]", TABLE))
    document = json.loads(json.dumps(profile_to_dict(load_profile(path))))
    assert document["device"]["transmission"] == {"stiffness": 20000.0, "damping": 2.0, "motor_mass": 0.3}
    assert document["device"]["velocity"] == "average"
