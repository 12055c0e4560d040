"""The manual's commissioning walk-through (docs/commissioning.md, "Commissioning a drive: scan, identify,
then run") runs by copy-paste: every ``$ `` command of that page's console blocks is typed, as it stands, into one
bash (in a fresh folder, bounded in time), and each command's exit status and key output are checked;
the simulated drive it starts in the background is stopped by the walk-through's own ``kill %1``.

What is checked against the simulated drive's hidden truth (m = 0.37 kg, b = 2.9 N s/m, Coulomb
0.2 N, 1000 counts of 0x606C noise, set by the walk-through's ``haptic-bus sim`` flags): the
identified ``m`` within 2 % and ``b`` within 3 %, Coulomb within 0.02 N, the delay 1 whole sample.
The page excites for 5 s (``--duration 5``: this test took 21.5 s on a quiet machine with
identify's default 20 s, 15.2 s with 5 s).  Measured with 5 s: m within 0.03 %, b within 0.22 %,
Coulomb within 0.0004 N (1 sigma 0.00011 kg, 0.0058 N s/m and 0.00028 N, about twice those of 20
s); the tolerances leave 14 to 67 times that for a loaded machine, whose stale cycles (TPDOs that
missed their timeout) the fit leaves out, and still catch a fit that mistakes the plant (a wrong
velocity model or delay moves m and b by tens of per cent).

The page's bus (udp_multicast group and port) is fixed, as a user types it; concurrent runs of this
test on one machine take turns (a file lock), and the port is outside the ranges the other tests
draw theirs from (conftest: 43200 and up).
"""

from __future__ import annotations

import fcntl
import pathlib
import re
import tempfile
from collections.abc import Iterator

import pytest

from tests.console import Shell, console_commands

REPO = pathlib.Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "commissioning.md"
LOCK = pathlib.Path(tempfile.gettempdir()) / "haptic-bus-readme-walkthrough.lock"
TRUTH = {"mass": 0.37, "friction": 2.9, "coulomb": 0.2}
EXPECTED = [  # each command of the page in order: how it starts, its exit status, the longest it may take (s)
    ("haptic-bus sim ", 0, 60),
    ("while ! grep -q ", 0, 120),  # until the simulator serves (it imports numpy, scipy, canopen first)
    ("haptic-bus scan ", 0, 120),
    ("haptic-bus profiles new my-handle --from-drive ", 0, 120),
    ("haptic-bus profiles check my-handle.toml", 2, 60),
    ("haptic-bus identify ", 0, 900),
    ("cat >> identified.toml <<'EOF'", 0, 10),
    ("haptic-bus profiles check identified.toml", 0, 60),
    ("haptic-bus run identified.toml ", 0, 300),
    ("kill %1", 0, 10),
]


@pytest.fixture
def shell(tmp_path: pathlib.Path) -> Iterator[Shell]:
    with open(LOCK, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the page's bus is one: one walk-through at a time on this machine
        bash = Shell(tmp_path)
        try:
            yield bash
        finally:
            bash.close()


def _number(pattern: str, text: str) -> float:
    found = re.search(pattern, text)
    assert found is not None, f"{pattern!r} not in {text}"
    return float(found.group(1))


def test_the_page_lists_the_walkthrough_in_order() -> None:
    commands = console_commands(PAGE.read_text())
    assert [c.text.split("\n")[0][:len(prefix)] for c, (prefix, _, _) in zip(commands, EXPECTED, strict=True)] == [
        prefix for prefix, _, _ in EXPECTED]


@pytest.mark.slow
def test_the_walkthrough_runs_as_it_stands(shell: Shell, tmp_path: pathlib.Path) -> None:
    commands = console_commands(PAGE.read_text())
    outputs: list[str] = []
    for command, (_, status, limit) in zip(commands, EXPECTED, strict=True):
        got, output = shell.type(command.text, limit)
        assert got == status, f"$ {command.text}\nexit {got}, expected {status}:\n{output}"
        outputs.append(output)
    sim, _, scan, new, first_check, identify, _, check, run, _ = outputs
    assert sim == ""  # its log goes to sim.log
    assert re.search(r"^\s+5\s+0x00020192\s+CiA-402 servo drive .* yes\s+yes\s+SWITCH ON DISABLED\s+0x0000$", scan, re.M), scan
    assert "from the drive rated_torque, max_torque_permille, position_per_count, force_per_torque, velocity_per_count" in new
    assert "still missing scene.objects" in first_check
    mass = _number(r"mass m\s+([0-9.e+-]+) kg", identify)
    friction = _number(r"viscous friction b\s+([0-9.e+-]+) N s/m", identify)
    coulomb = _number(r"Coulomb friction Fc\s+([0-9.e+-]+) N", identify)
    assert abs(mass - TRUTH["mass"]) <= 0.02 * TRUTH["mass"], identify
    assert abs(friction - TRUTH["friction"]) <= 0.03 * TRUTH["friction"], identify
    assert abs(coulomb - TRUTH["coulomb"]) <= 0.02, identify
    assert "whole samples: 1" in identify and "verdict: supported" in identify and "wrote identified.toml" in identify
    assert "profile verdict: passive; gate accepts" in check
    assert "cycles 2000;" in run and "ended: completed" in run
    status, _ = shell.type("wait %1", 30)  # the simulator stopped by the walk-through's kill: cleanly
    assert status == 0, (tmp_path / "sim.log").read_text()
    assert "SIGTERM received, stopping" in (tmp_path / "sim.log").read_text()
    assert (tmp_path / "run" / "record.csv").is_file() and (tmp_path / "run" / "run.json").is_file()
