"""break15: `check` with the quantisation condition on a wall whose passive K set is empty.

`haptic-bus check --mass 0.5 --friction 0.1 --period 1e-3 --stiffness 200 --damping 100
--velocity average --position-resolution 1e-6 --coulomb 0.5` printed a traceback
(IndexError in PassiveSet.at_most: `self.intervals[-1]` of an empty set) and exited 1, where the
same loop without `--position-resolution` says "NOT passive ... passive K at this B: none", exit 1.
"""

from __future__ import annotations

import pathlib
import subprocess
import sys

import haptic_bus as hb

LOOP = {"mass": 0.5, "friction": 0.1, "period": 1e-3, "stiffness": 200.0, "damping": 100.0}


def test_the_api_judges_a_wall_with_no_passive_k_under_quantisation() -> None:
    plain = hb.check_passivity(0.5, 0.1, 1e-3, 200.0, 100.0, velocity="average")
    assert not plain.passive  # the exact criterion: no K is passive at this B (margin -46.5 N s/m)
    report = hb.check_passivity(0.5, 0.1, 1e-3, 200.0, 100.0, velocity="average", position_resolution=1e-6, coulomb=0.5)
    assert not report.passive
    assert report.to_dict()["passive"] is False


def test_the_command_says_not_passive_in_one_verdict_without_a_traceback() -> None:
    args = [f"--{key}={value}" for key, value in LOOP.items()]
    done = subprocess.run(
        [sys.executable, "-c", "import sys; from haptic_bus.app.entry import main; sys.exit(main())", "check", *args,
         "--velocity", "average", "--position-resolution", "1e-6", "--coulomb", "0.5"],
        capture_output=True, text=True, timeout=120, check=False)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 1
    assert "NOT passive" in done.stdout


def test_profiles_check_says_not_passive_for_a_profile_stating_coulomb_friction(tmp_path: pathlib.Path) -> None:
    """The same through a profile: cia402-handle with `coulomb_friction = 0.5` and B = 200 N s/m (no passive
    K at this B): `haptic-bus profiles check` printed the same IndexError's traceback."""
    import profiles

    text = (pathlib.Path(profiles.__file__).parent / "cia402-handle.toml").read_text()
    for old, new in (('name = "cia402-handle"', 'name = "quantised-empty"'),
                     ("damping = 10.0 ", "damping = 200.0 "),
                     ('bandwidth = "strict"', 'bandwidth = "warn"'),
                     ("[device]\n", "[device]\ncoulomb_friction = 0.5\n")):
        assert old in text
        text = text.replace(old, new, 1)
    path = tmp_path / "quantised-empty.toml"
    path.write_text(text)
    done = subprocess.run(
        [sys.executable, "-c", "import sys; from haptic_bus.app.entry import main; sys.exit(main())", "profiles",
         "check", str(path)], capture_output=True, text=True, timeout=120, check=False)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 1
    assert "NOT passive" in done.stdout
