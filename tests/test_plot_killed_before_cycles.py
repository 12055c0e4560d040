"""``haptic-bus plot`` of a folder whose run was killed before its first cycle (a three-axis run
killed while it commissioned its drives): one line saying so, not a Python ``None``."""

from __future__ import annotations

import json
import pathlib

import pytest

from haptic_bus.app.cli import main
from haptic_bus.control.record import HEADER


def test_a_run_killed_before_its_first_cycle_is_refused_saying_so(tmp_path: pathlib.Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "run.json").write_text(json.dumps({"status": "running", "ended": False}))
    (tmp_path / "record.csv").write_text(HEADER)  # the header, no cycle
    assert main(["plot", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "None" not in err
    assert err.endswith("(this run has neither: run.json says 'running': the run was killed or crashed before its "
                        "first cycle)")
