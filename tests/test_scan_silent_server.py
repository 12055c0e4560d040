"""``haptic-bus scan --modbus`` of a server that accepts the connection and never answers (a stopped
process: SIGSTOP; here a socket nobody reads) is one line on stderr, exit 1: the failure and the unit ids
its --timeout left unprobed; it was two lines, the note first (break16)."""

from __future__ import annotations

import socket

import pytest

from haptic_bus.app.cli import main


def test_a_silent_server_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.create_server(("127.0.0.1", 0)) as server:  # the kernel accepts; nobody answers
        url = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        assert main(["scan", "--modbus", url, "--timeout", "0.2", "--answer-timeout", "0.05"]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert err.startswith(f"haptic-bus scan: no node answered at {url} within 0.2 s; unit ids "), err
    assert err.endswith("-247 not probed: --timeout 0.2 s spent (raise it, or narrow --unit-ids)\n"), err
