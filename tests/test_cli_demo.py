"""The main job and the profile commands, run the way a user runs them: the real command line
(:func:`haptic_bus.app.cli.main`) in this process (Ctrl-C of a demo process: ``test_cli_hygiene.py``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from PIL import Image

from haptic_bus.app.cli import main
from haptic_bus.app.demo import format_demo, run_demo
from haptic_bus.app.run_options import StopRequest


def _is_real_png(path: Path, min_colours: int = 8) -> bool:
    with Image.open(path) as image:
        image.verify()
    with Image.open(path) as image:
        colours = image.convert("RGB").getcolors(maxcolors=1 << 20)
    return path.stat().st_size > 10_000 and (colours is None or len(colours) >= min_colours)


def test_demo_runs_as_a_command_and_writes_real_plots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["demo", "--out", str(tmp_path)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "gate: passed" in out and "\ncycles: 2000 in virtual time; force saturated in 0\n" in out  # virtual said once
    assert "steady penetration: 2.0000 mm vs F/K = 2.0000 mm" in out
    for name in ("timeline.png", "force_position.png", "region.png"):
        assert _is_real_png(tmp_path / name), name
    rows = (tmp_path / "record.csv").read_text().splitlines()
    assert rows[0].startswith("time_s,wall_clock_s,monotonic_s,lateness_s,statusword,velocity_counts") and len(rows) == 2001


def test_demo_with_no_plots_writes_the_record_and_run_json_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--no-plots", "--duration", "0.1", "--out", str(tmp_path)]) == 0
    assert capsys.readouterr().out.endswith(f"wrote: {tmp_path / 'record.csv'}, {tmp_path / 'run.json'}\n")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["record.csv", "run.json"]
    assert len((tmp_path / "record.csv").read_text().splitlines()) == 1 + 100  # the header, 0.1 s at T = 1 ms


def test_profiles_check_matches_check(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profiles", "check", "seed-ideal"]) == 0
    assert "margin +0.0998139 N s/m" in capsys.readouterr().out
    assert main(["check", "--mass", "0.5", "--friction", "0.1", "--period", "0.001", "--stiffness", "200",
                 "--damping", "100", "--delay", "1"]) == 1


@pytest.mark.parametrize(("interrupted", "reason", "said"), [
    (False, "stopped", "run ended early (stopped)"),
    (True, "interrupted", "run ended early (interrupted): interrupted (Ctrl-C)"),
], ids=["sigterm", "ctrl-c"])
def test_a_demo_asked_to_stop_ends_at_a_cycle_boundary_and_says_how(interrupted: bool, reason: str, said: str,
                                                                    tmp_path: Path) -> None:
    """A SIGTERM killed ``haptic-bus demo`` (status 143, run.json left "running", no pictures; break18): the
    command now gives the demo a stop request, which SIGTERM and SIGINT set, as ``run``'s.  Here the
    request is set before the first cycle: no cycle runs, the folder is complete."""
    stop = StopRequest()
    stop.interrupted = interrupted
    stop.event.set()
    result = run_demo(tmp_path, seconds=0.1, plots=False, stop=stop)
    assert (result.summary.exit_reason, result.summary.cycles) == (reason, 0)
    assert format_demo(result).splitlines()[-2] == said
    document = json.loads((tmp_path / "run.json").read_text())
    assert (document["status"], document["ended"]) == (reason, True)
