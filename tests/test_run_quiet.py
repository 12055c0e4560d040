"""``run -q`` is what ``--help`` and docs/commands.md say: errors only.  A run that completes prints nothing
(no live view, no summary, no ``ended:`` line; its exit status and run.json say how it ended); a run that
fails prints its one error line on stderr.  ``--no-live`` keeps the summary and the ``ended:`` line.  (A new
user found ``run -q`` printing the summary and the ``ended:`` line, break round 16.)"""

from __future__ import annotations

import json
import pathlib

import pytest

from tests.run_rig import run_cli, simulated_drive


def test_run_q_that_completes_prints_nothing_and_no_live_prints_the_summary(
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    with simulated_drive("canopen", "cia402-handle") as drive:
        quiet = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.05",
                        "--no-plots", "--out", str(tmp_path / "quiet"), "-q")
    with simulated_drive("canopen", "cia402-handle") as drive:  # a drive at rest where the first run found its own
        summary = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.05",
                          "--no-plots", "--out", str(tmp_path / "summary"), "--no-live")
    assert (quiet.code, quiet.out, quiet.err) == (0, "", "")
    assert json.loads((tmp_path / "quiet" / "run.json").read_text())["exit_reason"] == "completed"
    assert summary.code == 0, summary.err
    lines = summary.out.splitlines()
    assert lines[0].startswith("cycles 50; peak force ") and lines[-1].startswith("ended: completed; wrote "), lines


def test_run_q_that_fails_prints_its_one_error_line_only(tmp_path: pathlib.Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    with simulated_drive("canopen", "cia402-handle") as drive:
        assert drive.enter_fault is not None
        drive.enter_fault(0x8250)
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.05",
                         "--no-plots", "--out", str(tmp_path / "run"), "-q")
    assert (result.code, result.out) == (1, "")
    assert result.err.count("\n") == 1 and result.err.startswith("haptic-bus run: drive error: CANopen node 5: drive "
                                                                  "is in FAULT"), result.err
