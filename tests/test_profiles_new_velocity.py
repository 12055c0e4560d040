"""``profiles new --velocity`` is checked as every other flag is, before the file is written: a window
longer than the new profile's period (``window:0.5`` at T = 1 ms) used to be written, and no reader could
load the profile it wrote; a bad model's line came from ``haptic-bus profiles`` and showed the value
rewritten (``'window:-1.0'`` for ``window:-1``) (break16)."""

from __future__ import annotations

import pathlib

import pytest

from haptic_bus.app.cli import main
from haptic_bus.app.profile_template import DEFAULT_PERIOD
from haptic_bus.profile.reader import read_document

SYNTAX = "'point', 'average', 'window:SECONDS' (SECONDS in (0, T]) or 'lowpass:SECONDS'"


@pytest.mark.parametrize(("model", "allowed"), [
    ("window:0.5", f"a window in (0, T] = (0, {DEFAULT_PERIOD:g}] s (the profile's loop.period)"),
    ("window:-1", SYNTAX), ("window:abc", SYNTAX), ("lowpass:inf", SYNTAX), ("foo", SYNTAX),
])
def test_a_velocity_model_the_profile_cannot_hold_is_refused_before_writing(
        model: str, allowed: str, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "new.toml"
    assert main(["profiles", "new", "new", "--velocity", model, "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert stdout == "" and not out.exists()
    assert err.startswith(f"haptic-bus profiles new: error: --velocity = '{model}' is invalid; allowed: {allowed}"), err
    assert err.count("\n") == 1


@pytest.mark.parametrize("model", ["window:0.001", "window:0.0005", "lowpass:0.002", "point", "average"])
def test_a_velocity_model_within_the_period_is_written(model: str, tmp_path: pathlib.Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "new.toml"
    assert main(["profiles", "new", "new", "--velocity", model, "--out", str(out)]) == 0
    capsys.readouterr()
    assert read_document(out)["device"]["velocity"] == model
