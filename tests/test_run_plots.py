"""Issue 20, plots that tell the story: a run with an upload, an alarm and a fault, then
``haptic-bus plot RUN_DIR``; each event is in the timeline, the fault in every title (in red), the
upload's scene on the K-B plane beside the profile's, force against position with the energy
the wall took and gave back.  ``multi-object`` names each of its five objects.

The real command line in this process, against the simulated drive on python-can's ``virtual``
bus (virtual time); the upload goes over SDO from another thread, as ``haptic-bus upload`` does.
The figures' texts are read from the figure objects the plot functions return; the PNGs were
opened and looked at while writing this test (see the final report of issue 20).
"""

from __future__ import annotations

import pathlib
import threading
import time
from collections.abc import Callable

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text

from haptic_bus.app import run_pictures
from haptic_bus.app.cli import main
from haptic_bus.app.demo import run_demo
from haptic_bus.app.kb_plane import kb_plane_figure
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.run_folder import RunFolder, read_run_folder
from haptic_bus.app.run_plots import (
    ending,
    force_position_figure,
    springs_energy_in_place,
    timeline_figure,
    wall_energy_taken_and_returned,
)
from haptic_bus.control.record import RecordTable
from haptic_bus.node.upload import upload_walls
from tests.run_rig import events_of, profile_variant, read_run, run_cli, simulated_drive

FAULT_CODE = 0x2310  # EMCY: continuous over-current
WAIT = 60.0  # s: the longest the orchestration waits for the run to reach a cycle (a bound, not a pace)


def _texts(figure: Figure) -> str:
    """Every text of a figure: titles, labels, annotations, legend entries."""
    return "\n".join(text.get_text() for text in figure.findobj(match=Text))


def _title(figure: Figure) -> Text:
    """The figure's title (``suptitle``) as the text artist it is drawn with."""
    return next(text for text in figure.texts if text.get_text() == figure.get_suptitle())


@pytest.fixture(scope="module")
def eventful_run(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """A run of cia402-handle with an accepted upload at about cycle 300, a late-cycle alarm (warn)
    from a TPDO the drive sent one byte short at about 600, and a drive fault at about 900."""
    folder = tmp_path_factory.mktemp("eventful")
    profile = profile_variant(folder, "cia402-handle", "eventful", extra='[supervisor]\non_late = "warn"\nlate_limit = 0\n')
    out = folder / "run"
    with simulated_drive("canopen", profile) as drive:
        answers: list[str] = []

        def at(cycle: int) -> None:
            deadline = time.monotonic() + WAIT
            while drive.drive.sync_count < cycle and time.monotonic() < deadline:
                time.sleep(0.002)

        def orchestrate() -> None:
            try:
                events()
            except BaseException:  # whatever failed here, the run must not go on for its 60 s
                drive.stop()
                raise

        def events() -> None:
            at(300)
            answers.append(upload_walls(drive.bus, 127, {0: (2500.0, 16.0)},
                                        timeout=5.0))
            at(drive.drive.sync_count + 300)
            assert drive.short_next_tpdo is not None and drive.enter_fault is not None
            drive.short_next_tpdo()
            at(drive.drive.sync_count + 300)
            drive.enter_fault(FAULT_CODE)

        thread = threading.Thread(target=orchestrate, daemon=True)
        thread.start()
        code = main(["run", str(profile), *drive.args, "--virtual-time", "--duration", "60", "--out", str(out), "-q",
                     "--no-plots"])  # haptic-bus plot draws them below
        thread.join(timeout=WAIT)
    assert code == 1 and answers and answers[0].startswith("accepted")
    return out


def test_the_run_recorded_the_upload_the_alarm_and_the_fault(eventful_run: pathlib.Path) -> None:
    document = read_run(eventful_run)
    assert document["exit_reason"] == "drive error" and document["ended"] is True
    (upload,) = events_of(document, "upload")
    (alarm,) = events_of(document, "alarm")
    (fault,) = events_of(document, "fault")
    assert upload["time_s"] < alarm["time_s"] < fault["time_s"]
    assert alarm["data"] == {"alarm": "late", "action": "warn"} and "did not renew in time" in alarm["message"]
    assert "0x2310" in fault["message"] or "2310" in fault["message"]
    assert [scene["origin"] for scene in document["scenes"]] == ["profile", "upload"]


def _keeping(draw: Callable[[RunFolder], Figure], name: str, drawn: dict[str, Figure]) -> Callable[[RunFolder], Figure]:
    """``draw`` as it is, each figure it returns also kept in ``drawn[name]``."""
    def keep(run: RunFolder) -> Figure:
        drawn[name] = draw(run)
        return drawn[name]

    return keep


def test_haptic_bus_plot_shows_every_event_and_the_fault(eventful_run: pathlib.Path, capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    written = [eventful_run / name for name in ("timeline.png", "force_position.png", "region.png")]
    assert not any(path.exists() for path in written)  # the run drew none (--no-plots)
    drawn: dict[str, Figure] = {}  # the figures the command saved, read below (drawing them again cost 1.3 s of CPU)
    for name in ("timeline_figure", "force_position_figure", "kb_plane_figure"):
        monkeypatch.setattr(run_pictures, name, _keeping(getattr(run_pictures, name), name, drawn))
    result = run_cli(capsys, "plot", str(eventful_run))
    assert result.code == 0 and result.err == ""
    assert result.out == f"wrote {', '.join(map(str, written))}\n"
    assert all(path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 30_000 for path in written)

    run = read_run_folder(eventful_run)
    timeline = drawn["timeline_figure"]
    texts = _texts(timeline)
    assert "upload: upload accepted as scene 1" in texts
    assert "alarm: " in texts and "fault: " in texts
    assert {"event: upload", "event: alarm", "event: fault"} <= set(texts.splitlines())
    title = _title(timeline)  # the exit reason, in red: a faulted run must not look healthy
    assert "ended: drive error" in title.get_text() and title.get_color() == "tab:red"
    events = {line.get_xdata()[0] for line in timeline.axes[0].lines if line.get_linestyle() == "-" and
              len(line.get_xdata()) == 2 and line.get_xdata()[0] == line.get_xdata()[1]}
    assert {e["time_s"] for e in run.document["events"] if e["kind"] in ("upload", "alarm", "fault")} <= events

    plane = drawn["kb_plane_figure"]
    texts = _texts(plane)
    assert "scene 0 (profile): end-stop K 1500 N/m, B 10 N s/m, margin +11.1 N s/m" in texts
    assert "scene 1 (upload): end-stop K 2500 N/m, B 16 N s/m, margin +5.7 N s/m" in texts
    assert "D = 1 samples, average velocity" in _title(plane).get_text() and _title(plane).get_color() == "tab:red"

    loop = drawn["force_position_figure"]
    assert run.record is not None
    taken, returned = wall_energy_taken_and_returned(run.record["position_m"], run.record["force_n"])
    assert taken > returned > 0  # a passive wall gives back less than it took
    assert f"the wall took {taken * 1e3:.4g} mJ and gave back {returned * 1e3:.4g} mJ" in _title(loop).get_text()


def test_multi_object_draws_each_of_its_five_objects(tmp_path: pathlib.Path) -> None:
    result = run_demo(tmp_path, load_profile("multi-object"), 1.0, plots=False)  # the figures are drawn below
    assert result.summary.exit_reason == "completed"
    run = read_run_folder(tmp_path)
    names = ("workspace (slot)", "front-stop (wall)", "home (detent)", "left-index (detent)", "right-index (detent)")
    timeline = timeline_figure(run)
    assert set(names) <= set(_texts(timeline).splitlines())
    plt.close(timeline)
    loop = force_position_figure(run)
    texts = _texts(loop)
    assert all(f"{name.split(' ')[0]}: K " in texts for name in names)
    plt.close(loop)
    plane = kb_plane_figure(run)
    walls = [line for line in _texts(plane).splitlines() if line.startswith("scene 0 (profile): ")]
    assert len(walls) == 5 and np.all([" K " in w for w in walls])  # the five contact walls the gate judged
    plt.close(plane)


REGION = ["region", "--mass", "1", "--friction", "20", "--period", "0.001", "--delay", "1", "--velocity", "average"]


@pytest.mark.parametrize("args, line", [
    ([*REGION, "--png", "{file}/x.png"], "haptic-bus region: error: --png = '{file}/x.png' is invalid; allowed: a "
                                         "file this user can create and write ({file} is a file, not a folder)"),
    ([*REGION, "--png", "{tmp}/r.png", "--mark", "0,10"],
     "haptic-bus region: error: argument --mark: '0,10': K and B must be finite and > 0 (alpha = B/(KT) and beta = b/B "
     "are points of the plane only then)"),
    ([*REGION, "--png", "{tmp}/r.png", "--mark", "1500"], "haptic-bus region: error: argument --mark: '1500' is not K,B "
                                                           "(two numbers: N/m, N s/m)"),
    (["plot", "{tmp}"], "haptic-bus plot: error: RUN_DIR = '{tmp}' is invalid; allowed: a run folder: one with "
                        "run.json (written by haptic-bus run or demo)"),
    (["plot", ""], "haptic-bus plot: error: RUN_DIR = '' is invalid; allowed: a folder path (empty: none given)"),  # '.'
], ids=["png-under-a-file", "mark-zero", "mark-one-number", "plot-not-a-run", "plot-empty"])
def test_bad_output_and_marks_are_one_line_and_exit_2(args: list[str], line: str, tmp_path: pathlib.Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "afile").write_text("not a folder")
    values = {"file": str(tmp_path / "afile"), "tmp": str(tmp_path)}
    result = run_cli(capsys, *[arg.format(**values) for arg in args])
    assert (result.code, result.out, result.err_lines) == (2, "", [line.format(**values)])
    assert not (tmp_path / "r.png").exists()


def test_region_marks_walls_with_their_verdicts(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    result = run_cli(capsys, *REGION, "--png", str(tmp_path / "r"), "--mark", "1500,10", "--mark", "30000,2")
    assert result.code == 0 and result.out == f"wrote {tmp_path / 'r.png'}\n"
    assert (tmp_path / "r.png").stat().st_size > 30_000


@pytest.mark.parametrize("document, said", [
    ({"exit_reason": "interrupted", "error": "interrupted (Ctrl-C)"}, "ended: interrupted (Ctrl-C)"),
    ({"exit_reason": "drive error", "error": "CANopen node 5: EMCY 0x2310"}, "ended: drive error: CANopen node 5: EMCY 0x2310"),
    ({"exit_reason": "stopped", "error": None}, "ended: stopped"),
    ({"status": "completed"}, "ended: completed"),
], ids=["error-starting-with-the-reason", "error-beside-the-reason", "no-error", "status-only"])
def test_the_title_says_how_the_run_ended_once(document: dict[str, object], said: str, tmp_path: pathlib.Path) -> None:
    """A Ctrl-C'd run's title read "ended: interrupted (interrupted (Ctrl-C))" (break18): an error that
    begins with the exit reason is said alone."""
    assert ending(RunFolder(tmp_path, {"ended": True, **document}, None)) == (said, document.get("error") is None)


def test_force_position_counts_what_a_start_ramp_gave_the_springs_in_place(tmp_path: pathlib.Path) -> None:
    """break18b: a run started 2 mm inside cia402-handle's wall with ``--start-in-contact ramp`` drew "net -20.45 mJ
    into it (... below zero the wall would have made energy)" while the port's energy stayed above 0 J: raising K
    with the handle inside gives the springs energy no ``u dx`` brings.  Here the scale ramps 0 -> 1 over 500
    cycles with the handle held p = 2 mm inside a 1500 N/m spring (B = 0), then leaves in 1000 steps of
    d = 2 um: the springs got K p^2 / 2 = 3 mJ in place (exact but rounding: the scale's steps sum to 1), and
    the wall's sum of ``u_k dx_k`` (each force held over its step, the left sum of K (p - x) dx) is -K p (p + d)
    / 2: the two add to -K p d / 2 = -3 uJ, the left sum's own error, not energy made."""
    K, p, d, surface = 1500.0, 2e-3, 2e-6, 0.003
    wall = {"kind": "wall", "name": "end-stop", "position": surface, "normal": -1, "stiffness": K, "damping": 0.0}
    held = np.full(500, surface + p)
    leaving = surface + p - d * np.arange(1001)
    position = np.concatenate([held, leaving, np.full(10, surface - 1e-3)])
    scale = np.concatenate([np.arange(1, 501) / 500, np.ones(1011)])
    force = scale * K * np.maximum(position - surface, 0.0)
    columns = {"time_s": np.arange(position.size) * 1e-3, "position_m": position, "force_n": force, "scale": scale,
               "scene_id": np.zeros(position.size), "energy_j": np.zeros(position.size)}
    document = {"ended": True, "status": "completed", "profile": {"name": "ramp"},
                "scenes": [{"scene_id": 0, "objects": [wall]}]}
    record = RecordTable(columns, torn_line=False)
    in_place = springs_energy_in_place(document, record)
    assert in_place == pytest.approx(K * p**2 / 2, rel=1e-12)
    taken, returned = wall_energy_taken_and_returned(position, force)
    assert taken == 0.0 and taken - returned == pytest.approx(-K * p * (p + d) / 2, rel=1e-9)
    assert taken - returned + in_place == pytest.approx(-K * p * d / 2, rel=1e-6)
    figure = force_position_figure(RunFolder(tmp_path, document, record))
    try:
        title = " ".join(figure.get_suptitle().split())
    finally:
        plt.close(figure)
    assert "net -3.003 mJ, and its springs got 3 mJ with no u dx (held at the start, or gained in place by a ramp, " \
           "derate or upload with the handle inside): -0.003 mJ (held in its springs at the end" in title, title
