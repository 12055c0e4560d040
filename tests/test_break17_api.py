"""A new user's misuse of the public API (helper break17): each case a defect found and fixed."""
from __future__ import annotations

import pathlib

import can
import pytest

import haptic_bus as hb


def test_a_shut_down_bus_is_refused_before_any_file(tmp_path: pathlib.Path) -> None:
    """hb.run on a can.BusABC the caller already shut down: one ParameterError naming the bus, no run
    folder (it was a flood of receive errors on stderr, then python-can's CanOperationError raw and a
    run.json saying "crashed")."""
    bus = can.Bus(interface="virtual", channel="break17-closed")
    bus.shutdown()
    out = tmp_path / "run"
    with pytest.raises(hb.ParameterError, match=r"^run: bus = .* is invalid; allowed: an open can.BusABC "
                                                r"\(this one is shut down\)$"):
        hb.run(hb.load_profile("cia402-handle"), bus, hb.RunOptions(duration=0.1, pacing="virtual", out_dir=out),
               node_id=5)
    assert not out.exists()
