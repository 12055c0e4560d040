"""`haptic-bus check --coulomb N` is used only by the quantisation condition: without
`--position-resolution` it is refused in one line (exit 2) instead of being silently ignored (the
verdict said "passive" whatever the Coulomb friction, with nothing about it)."""

from __future__ import annotations

import pytest

from haptic_bus.app.cli import main

WALL = ["check", "--mass", "0.032", "--friction", "3.62", "--period", "0.001", "--stiffness", "1500", "--damping", "0",
        "--velocity", "average", "--delay", "1"]


def test_coulomb_without_a_resolution_is_refused_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*WALL, "--coulomb", "0.1"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and "--coulomb" in captured.err and "--position-resolution" in captured.err


def test_the_issue_numbers_still_hold(capsys: pytest.CaptureFixture[str]) -> None:
    # issue 27: at 50 um per count the wall needs K Delta/2 = 0.0375 N; 0 N fails (1), 0.1 N passes (0)
    assert main([*WALL, "--position-resolution", "5e-5", "--coulomb", "0"]) == 1
    assert main([*WALL, "--position-resolution", "5e-5", "--coulomb", "0.1"]) == 0
    assert main([*WALL, "--position-resolution", "5e-5"]) == 1  # no --coulomb: 0 N
    capsys.readouterr()
