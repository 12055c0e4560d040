"""``haptic-bus sim`` with several axes takes its flags as with one, or refuses them in one line, exit 2
(break16):

* ``--node-ids`` dropped ``--bus-kwargs`` (its slaves served python-can's default udp_multicast port, where
  a master given the same ``--bus-kwargs`` found nobody) and let ``--bitrate -5`` through to the bus' open
  (exit 1, where an invalid input is exit 2);
* a hidden-truth or operator flag (``--mass``, ``--operator``, ``--extra-delay`` ...) with a multi-axis
  ``--profile`` was dropped without a word: each axis takes its truth from its ``[[axes]]`` entry;
* the same ``--modbus`` address twice was "Could not start listen", exit 1;
* a flag's text that is no number (``--mass x``, ``--unit-id x``) was argparse's line without a range.
"""

from __future__ import annotations

from typing import Any

import pytest

import sim_drive.canopen.multi_axis as multi_axis
from haptic_bus.app.cli import main
from haptic_bus.errors import ParameterError

BUS = ["--interface", "udp_multicast", "--channel", "239.74.163.169"]


def test_node_ids_open_the_bus_the_bus_options_name(monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]) -> None:
    seen: list[dict[str, Any]] = []

    def opened(config: dict[str, Any], *args: object, **kwargs: object) -> None:
        seen.append(config)  # the configuration the slaves would open, and nothing opened
        raise ParameterError("stop", "here", "the test's stop")

    monkeypatch.setattr(multi_axis, "MultiAxisSim", opened)
    assert main(["sim", *BUS, "--bus-kwargs", "port=44169", "--node-ids", "5,6,7"]) == 2
    assert seen == [{"interface": "udp_multicast", "channel": "239.74.163.169", "port": 44169}]
    assert main(["sim", *BUS, "--bus-option", "port=44169", "--bitrate", "500000", "--node-ids", "5,6,7"]) == 2
    assert seen[-1] == {"interface": "udp_multicast", "channel": "239.74.163.169", "bitrate": 500000, "port": 44169}
    capfd.readouterr()


@pytest.mark.parametrize(("argv", "line"), [
    ([*BUS, "--bus-option", "port=44169", "--node-ids", "5,6,7", "--bitrate", "-5"],
     "CAN bus: bitrate = -5 is invalid; allowed: a finite real in [1000, 1e+06] bit/s"),
    ([*BUS, "--bus-option", "port=44169", "--bus-kwargs", "port=44168", "--node-ids", "5,6,7"],
     "bus argument port = 44168 is invalid; allowed: one value per key (port = 44169 is given too)"),
    ([*BUS, "--bus-option", "port=44169", "--node-ids", "5,6,7", "--profile", "gantry-3d", "--mass", "3"],
     "--mass = 3.0 is invalid; allowed: none with a multi-axis --profile: each axis' hidden truth is its [[axes]] "
     "entry's [axes.device] and the hand is [space.operator] (edit a copy of the profile)"),
    ([*BUS, "--bus-option", "port=44169", "--node-ids", "5,6,7", "--profile", "gantry-3d", "--operator", "constant:3"],
     "--operator = 'constant:3' is invalid; allowed: none with a multi-axis --profile"),
    (["--modbus", "tcp://127.0.0.1:0", "--unit-ids", "1,2,3", "--profile", "gantry-3d", "--extra-delay", "0.5"],
     "--extra-delay = 0.5 is invalid; allowed: none with a multi-axis --profile"),
    (["--modbus", "tcp://127.0.0.1:44169", "--modbus", "tcp://127.0.0.1:44169", "--modbus", "tcp://127.0.0.1:44168",
      "--profile", "gantry-3d"],
     "--modbus = 'tcp://127.0.0.1:44169' is invalid; allowed: each address once (3 given, this one twice): every "
     "--modbus is a server of its own"),
    ([*BUS, "--bus-option", "port=44169", "--node-id", "5", "--mass", "x"],
     "--mass = 'x' is invalid; allowed: a finite real in [1e-09, 1e+09] kg"),
    (["--modbus", "tcp://127.0.0.1:0", "--unit-id", "x"], "--unit-id = 'x' is invalid; allowed: Modbus unit ids 1..247"),
])
def test_a_flag_several_axes_cannot_take_is_one_line_exit_2(argv: list[str], line: str,
                                                             capfd: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", *argv]) == 2
    out, err = capfd.readouterr()
    assert out == "" and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"haptic-bus sim: error: {line}"), err
