"""A new user's misuse of the public API (helper break17): each case a defect found and fixed."""
from __future__ import annotations

import logging
import pathlib

import can
import pytest

import haptic_bus as hb
from drives.canopen.link import ReceiveErrors


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


def test_receive_errors_are_all_counted_but_logged_by_decades(caplog: pytest.LogCaptureFixture) -> None:
    """A notifier whose bus fails every receive: the first error kept, every one counted, the log
    lines at the 1st, 10th and 100th error, not one per error."""
    listener = ReceiveErrors("node 5")
    errors = [can.CanOperationError(f"closed {i}") for i in range(150)]
    with caplog.at_level(logging.WARNING, logger="drives.canopen.link"):
        for error in errors:
            listener.on_error(error)
    assert listener.count == 150
    assert listener.error is errors[0]
    lines = [record.getMessage() for record in caplog.records]
    assert lines == ["node 5: CAN receive failed: CanOperationError('closed 0')",
                     "node 5: CAN receive failed: CanOperationError('closed 9') (10 receive errors so far)",
                     "node 5: CAN receive failed: CanOperationError('closed 99') (100 receive errors so far)"]


@pytest.mark.parametrize("argument", [5, None, b"cia402-handle", ["cia402-handle"]])
def test_load_profile_refuses_what_is_neither_a_name_nor_a_path(argument: object) -> None:
    """hb.load_profile(5) was pathlib's TypeError; the docs promise a ParameterError naming the field."""
    with pytest.raises(hb.ParameterError, match=r"^profile .*: profile = .* is invalid; allowed: a shipped profile "
                                                r"name or a TOML file's path \(str or pathlib.Path\)$"):
        hb.load_profile(argument)  # type: ignore[arg-type]  # what a user may pass
