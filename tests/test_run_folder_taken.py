"""A run's folder is its own: a second run into it is refused, and a folder deleted under a run is one line.

Seen with ``haptic-bus run ... --out same`` twice (the second started 4 s into the first): the
second was not refused for the folder; it replaced the first's ``run.json`` with its own while
the first went on.  And ``rm -rf`` of a running run's folder ended the run with a traceback
(``FileNotFoundError: 'del_a/.run.json.tmp'``) where the command promises one line, after
waiting 30 s for the writer, which had stopped at its failed write without saying what it wrote.
"""

from __future__ import annotations

import json
import logging
import shutil
import threading
import time

import pytest

import haptic_bus as hb
from haptic_bus.app import cli
from haptic_bus.app.run_folder import prepare_run_folder
from haptic_bus.errors import HapticBusError, ParameterError


def _run_json(folder, **document):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "run.json").write_text(json.dumps(document))


def test_an_out_folder_whose_run_has_not_ended_is_refused_before_any_bus(tmp_path, capsys):
    taken = tmp_path / "taken"
    _run_json(taken, status="running", ended=False)
    status = cli.main(["run", "cia402-handle", "--interface", "virtual", "--channel", "folder-taken", "--node-id", "5",
                       "--virtual-time", "--duration", "0.01", "--out", str(taken)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and "has not ended" in err and "'running'" in err
    assert json.loads((taken / "run.json").read_text()) == {"status": "running", "ended": False}  # left as it was


def test_a_folder_whose_run_ended_or_without_a_run_is_taken(tmp_path):
    ended = tmp_path / "ended"
    _run_json(ended, status="completed", ended=True)
    assert prepare_run_folder(ended, "cia402-handle") == ended
    assert prepare_run_folder(tmp_path / "new", "cia402-handle") == tmp_path / "new"
    with pytest.raises(ParameterError, match="has not ended"):
        _run_json(tmp_path / "killed", status="running", ended=False)
        prepare_run_folder(tmp_path / "killed", "cia402-handle")


def test_a_folder_deleted_under_a_running_run_ends_it_in_one_error(haptic_sim, tmp_path, caplog):
    caplog.set_level(logging.ERROR)
    drive = haptic_sim("cia402-handle", interface="lockstep")
    folder = tmp_path / "deleted"

    def delete_once_written() -> None:
        deadline = time.monotonic() + 60.0
        while not (folder / "record.csv").exists() and time.monotonic() < deadline:
            time.sleep(0.005)
        shutil.rmtree(folder, ignore_errors=True)

    deleter = threading.Thread(target=delete_once_written, name="test-deleter")
    deleter.start()
    try:
        with pytest.raises(HapticBusError, match=r"cannot complete run\.json .* deleted while the run went on\? "
                                                 r"The run ended completed"):
            hb.run(hb.load_profile("cia402-handle"), drive.bus,
                   hb.RunOptions(duration=2.0, pacing="virtual", out_dir=folder, plots=False), node_id=5)
    finally:
        deleter.join(timeout=60.0)
    assert not [r for r in caplog.records if "did not answer" in r.getMessage()]  # the writer's stats came at once
