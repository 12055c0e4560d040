"""hb.RunOptions and hb.run refuse a value of the wrong kind in one ParameterError naming it and
what is allowed, before any bus or file is touched (breaker11a: ``reset_fault="no"`` was taken as
True, ``out_dir=5``, ``stop="x"`` and ``options=None`` ended in a TypeError or AttributeError)."""

from __future__ import annotations

import pathlib
from typing import Any

import pytest

import haptic_bus as hb
from haptic_bus.app.run_options import StopRequest
from haptic_bus.errors import ParameterError


@pytest.mark.parametrize(("field", "value", "allowed"), [
    ("reset_fault", "no", "True or False"),
    ("live", 1, "True or False"),
    ("bus_log", None, "True or False"),
    ("plots", "false", "True or False"),
    ("out_dir", 5, "None (runs/<UTC>-<profile>) or a folder's path"),
    ("stop", "x", "a StopRequest"),
])
def test_a_run_option_of_the_wrong_kind_is_named(field: str, value: Any, allowed: str) -> None:
    with pytest.raises(ParameterError) as caught:
        hb.RunOptions(duration=1.0, **{field: value})
    assert caught.value.name == field
    assert caught.value.allowed == allowed
    assert str(caught.value).count("\n") == 0


def test_the_kinds_a_caller_gives_are_taken(tmp_path: pathlib.Path) -> None:
    options = hb.RunOptions(duration=1.0, out_dir=str(tmp_path), reset_fault=True, live=False, bus_log=False,
                            plots=False, stop=StopRequest())
    assert (options.out_dir, options.reset_fault, options.live) == (str(tmp_path), True, False)


def test_run_without_run_options_is_refused_before_the_bus() -> None:
    profile = hb.load_profile("gantry-3d")
    bus = {"interface": "nosuch-interface-never-opened", "channel": "x"}
    with pytest.raises(ParameterError) as caught:
        hb.run(profile, bus, None)  # type: ignore[arg-type]  # what a caller may pass
    assert caught.value.name == "options"
    assert "RunOptions" in caught.value.allowed
