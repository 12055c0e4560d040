"""``haptic-bus bench --only preflight`` says what happened in every run, the ones that never
reached pre-flight too: a simulated drive that did not start, a run that ended on a drive error
before pre-flight, a run that did not exit within its wait (killed).  Each is a row of section 11
naming it, counted in the summary and in issue 26's Done-when row 3, and the other runs are kept
(such a run used to end the whole section as "unavailable", or to be shown as a refusal)."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest

from haptic_bus.bench import preflight_runs, processes, run_bench, startup
from haptic_bus.bench.size import QUICK, SMOKE
from haptic_bus.testing.buses import unique_multicast
from tests import short_preflight


@pytest.fixture
def no_drive(multicast: tuple[str, int]) -> dict:
    """A udp_multicast bus of this test's own where nothing answers."""
    group, port = multicast
    return {"interface": "udp_multicast", "channel": group, "port": port}


@pytest.fixture(scope="module")
def ended_before_preflight() -> dict:
    """:func:`preflight_runs.one_run` on a udp_multicast bus of this module's own where nothing answers: the
    command line's run ends (exit 1) on the boot-up it waits for.  One such run serves the tests that read one.
    Its master's two waits for the drive (statusword, boot-up) take 0.1 s each, not the default 1 s
    (:mod:`tests.short_preflight`): the run ends on the same error at any length of them."""
    group, port = unique_multicast()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(startup, "haptic_bus_command", lambda: short_preflight.command(boot_timeout=0.1))
        return preflight_runs.one_run({"interface": "udp_multicast", "channel": group, "port": port})


def test_a_simulator_that_does_not_start_is_a_run_that_never_reached_preflight(tmp_path: Path,
                                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(processes, "START_WAIT", 0.01)  # s: far shorter than the simulator's imports
    result = run_bench(tmp_path, SMOKE, sections=("preflight",))
    section = json.loads((tmp_path / "bench.json").read_text())["sections"]["preflight"]
    assert section["available"] is True
    assert (section["count"], section["held"], section["refused"], section["not_reached"]) == (1, 0, 0, 1)
    (entry,) = section["runs"]
    assert entry["exit"] is None
    assert entry["error"] == "the simulated drive did not start: no heartbeat of node 5 within 0.01 s"
    text = (tmp_path / "bench.md").read_text()
    assert ("| 1 | - | not reached | - | - | - | the simulated drive did not start: no heartbeat of node 5 within "
            "0.01 s |") in text
    assert "0 of 1 passed pre-flight, 0 refused, 1 never reached it;" in text
    (row,) = [r for r in result["done_when_26"] if r["line"] == 3]
    assert (row["measured"], row["result"]) == ("0 of 1", "FAIL")
    assert row["note"] == "0 held T, 0 refused, 1 never reached pre-flight"


def test_a_run_that_ends_before_preflight_names_its_error(ended_before_preflight: dict) -> None:
    entry = ended_before_preflight
    assert entry["exit"] == 1 and entry["exit_reason"] == "drive error"
    assert not preflight_runs.reached(entry) and entry["lateness_p99_s"] is None
    assert entry["error"].startswith("CANopen node 5: no SDO answer within 0.1 s before NMT reset communication and "
                                     "no boot-up within 0.1 s after it")


def test_a_run_that_does_not_exit_in_time_is_killed_and_said(no_drive: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(preflight_runs, "RUN_WAIT", 0.5)  # s: the command line's imports alone take longer
    entry = preflight_runs.one_run(no_drive)
    assert (entry["exit"], entry["exit_reason"]) == (None, "timed out")
    assert entry["error"] == "no exit within 0.5 s: killed"
    assert not preflight_runs.reached(entry)


def test_ctrl_c_keeps_the_runs_that_finished(ended_before_preflight: dict, tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """The first run is the module's run that ended before pre-flight (what a Ctrl-C keeps does not depend on
    how a run ended, and it spares a simulator's process and a pre-flight's real-time cycles); the Ctrl-C
    lands as the second starts."""
    started = []

    def ctrl_c_in_the_second() -> dict:
        started.append(len(started) + 1)
        if len(started) == 2:
            signal.raise_signal(signal.SIGINT)  # Ctrl-C as the second run starts
        return ended_before_preflight

    monkeypatch.setattr(preflight_runs, "fresh_run", ctrl_c_in_the_second)
    result = run_bench(tmp_path, QUICK, sections=("preflight",))
    assert started == [1, 2] and result["interrupted"] == "preflight"
    section = json.loads((tmp_path / "bench.json").read_text())["sections"]["preflight"]
    assert (section["count"], section["planned"], section["interrupted"], len(section["runs"])) == (1, 5, True, 1)
    assert section["runs"][0]["exit"] == 1  # the first run ran to its end
    text = (tmp_path / "bench.md").read_text()
    assert "**Interrupted (Ctrl-C) in section preflight: only the sections before it ran, and what of it finished.**" in text
    assert "each time: 1 of 5 runs (interrupted: Ctrl-C), one after another." in text
    (row,) = [r for r in result["done_when_26"] if r["line"] == 3]
    assert (row["target"], row["result"]) == ("5 of 5", "n/a")
    assert row["note"].startswith("interrupted (Ctrl-C) after 1 of 5 runs; ")
