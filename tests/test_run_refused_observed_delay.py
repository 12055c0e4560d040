"""A real-time run refused at pre-flight records no observed loop delay: its control loop never
cycled, so ``run.json``'s ``loop`` has no ``delay_observed`` (breaker14: it said 1.0, the assumed
delay over an empty window, beside pre-flight's ``observed_delay`` of 1.36 samples).

The run is refused whatever this machine's timing: stiff-wall with ``[passivity] layer = "off"``
and its gate's safety margin set to the wall's own margin at the assumed delay (less 1e-6 N s/m)
passes the gate at D = 1 and fails it at any measured delay 1e-7 samples beyond (the margin falls
about 12 N s/m per sample there: 1.084 at D = 1, 0.848 at 1.02), a delay-added p99 of 0.1 ns at
T = 1 ms; a timing pre-flight cannot hold refuses it too.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import haptic_bus as hb
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.profiles.one_axis import Profile
from haptic_bus.app.run_json import read_document


def _edge_profile(folder: Path) -> Path:
    """stiff-wall, no passivity layer, the gate's safety margin at the wall's margin at D = 1."""
    shipped = load_profile("stiff-wall")
    assert isinstance(shipped, Profile) and shipped.path is not None
    margin = shipped.judge().walls[0].verdict.margin
    text = shipped.path.read_text()
    text = re.sub(r'(?m)^name = "stiff-wall"', 'name = "stiff-wall-edge"', text)
    text = re.sub(r"(?m)^safety_margin = [0-9.]+", f"safety_margin = {margin - 1e-6:.9f}", text)
    path = folder / "stiff-wall-edge.toml"
    path.write_text(text + '\n[passivity]\nlayer = "off"\n')
    return path


def test_refused_at_preflight_records_no_observed_delay(haptic_sim: Callable[..., Any], tmp_path: Path) -> None:
    """In this process on the lock-step bus, paced by the wall clock: the run's own pre-flight."""
    profile = _edge_profile(tmp_path)
    drive = haptic_sim("stiff-wall", interface="lockstep")
    options = hb.RunOptions(duration=0.05, pacing="wall", out_dir=tmp_path / "run", live=False, bus_log=False,
                            plots=False, preflight_cycles=50)
    result = hb.run(hb.load_profile(profile), drive.bus, options, **drive.run_kwargs())
    document = read_document(tmp_path / "run")
    assert result.exit_reason == "refused", result.error
    assert document["status"] == "refused"
    assert document["preflight"]["holdable"] is False
    assert document["preflight"]["observed_delay"] > 1.0
    assert "delay_observed" not in document["loop"]
    assert document["loop"]["delay_assumed"] == 1
