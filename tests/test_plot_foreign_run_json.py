"""``haptic-bus plot`` of a run folder whose run.json holds a field the pictures read in a shape they
cannot draw (one another version wrote, or one edited by hand: ``"events": null``, ``"gate_loop": {"m":
"x"}``, ``"profile": []``, a sphere without its radius) is one line naming the field, exit 2, as an
unreadable run folder is; it was a TypeError's, KeyError's or AttributeError's traceback from deep in the
drawing, exit 1 (break16).  A field left out stays allowed, as before."""

from __future__ import annotations

import json
import pathlib
from typing import Any

import pytest

from haptic_bus.app.cli import main
from haptic_bus.app.run_folder import read_run_folder
from haptic_bus.app.run_json_shape import check_drawn_fields

ONE_AXIS: dict[str, Any] = {
    "profile": {"name": "p"},
    "events": [{"time_s": 0.0, "kind": "start", "message": "m"}],
    "scenes": [{"scene_id": 0, "origin": "profile",
                "objects": [{"kind": "wall", "name": "end-stop", "position": 0.003, "normal": -1, "stiffness": 1500.0,
                             "damping": 10.0}],
                "walls": [{"objects": ["end-stop"], "K": 1500.0, "B": 10.0, "margin": 11.09}]}],
    "gate_loop": {"m": 1.0, "b": 20.0, "T": 0.001, "delay": 1.0, "velocity": "average"},
    "loop": {"period": 0.001},
    "settings": {},
}
SPHERE = {"kind": "sphere", "name": "ball", "center": [0.0, -0.03, 0.0], "radius": 0.01, "stiffness": 1500.0,
          "damping": 5.0}
AXES: dict[str, Any] = {"settings": {"axes": [{"name": "x"}, {"name": "y"}, {"name": "z"}]},
                        "scenes": [{"scene_id": 0, "origin": "profile", "objects": [SPHERE], "walls": []}]}


def _with(document: dict[str, Any], path: tuple[str | int, ...], value: object) -> dict[str, Any]:
    changed = json.loads(json.dumps(document))
    where = changed
    for key in path[:-1]:
        where = where[key]
    if value is _GONE:
        del where[path[-1]]
    else:
        where[path[-1]] = value
    return changed


_GONE = object()


def test_the_fields_as_a_run_writes_them_and_left_out_pass() -> None:
    check_drawn_fields(ONE_AXIS)
    check_drawn_fields(AXES)
    check_drawn_fields({})  # a run that never began: nothing to draw, nothing refused here
    for key in ONE_AXIS:
        check_drawn_fields(_with(ONE_AXIS, (key,), _GONE))


@pytest.mark.parametrize(("document", "says"), [
    (_with(ONE_AXIS, ("events",), None), "run.json's events = None is invalid; allowed: a list of JSON objects"),
    (_with(ONE_AXIS, ("events", 0, "time_s"), "x"), "run.json's events[0].time_s = 'x' is invalid; allowed: a number"),
    (_with(ONE_AXIS, ("profile",), []), "run.json's profile = [] is invalid; allowed: a JSON object"),
    (_with(ONE_AXIS, ("gate_loop",), None), "run.json's gate_loop = None is invalid; allowed: a JSON object"),
    (_with(ONE_AXIS, ("gate_loop", "m"), "x"), "run.json's gate_loop.m = 'x' is invalid; allowed: a number"),
    (_with(ONE_AXIS, ("gate_loop", "T"), _GONE), "run.json's gate_loop.T is missing"),
    (_with(ONE_AXIS, ("scenes", 0, "walls", 0, "K"), None), "run.json's scenes[0].walls[0].K = None is invalid"),
    (_with(ONE_AXIS, ("scenes", 0, "scene_id"), "0"), "run.json's scenes[0].scene_id = '0' is invalid; allowed: an integer"),
    (_with(ONE_AXIS, ("scenes", 0, "objects", 0, "stiffness"), "x"), "run.json's scenes[0].objects[0]: "),
    (_with(ONE_AXIS, ("scenes", 0, "objects", 0, "name"), []), "run.json's scenes[0].objects[0].name = [] is invalid; "
                                                                "allowed: a text"),
    (_with(ONE_AXIS, ("scenes", 0, "walls", 0, "objects", 0), 3), "run.json's scenes[0].walls[0].objects = [3] is invalid; "
                                                                  "allowed: a list of object names"),
    (_with(ONE_AXIS, ("loop", "period"), None), "run.json's loop.period = None is invalid; allowed: a number"),
    (_with(ONE_AXIS, ("settings",), "x"), "run.json's settings = 'x' is invalid; allowed: a JSON object"),
    (_with(AXES, ("settings", "axes", 1), {}), "run.json's settings.axes[1].name is missing"),
    (_with(AXES, ("scenes", 0, "objects", 0, "center"), -1),
     "run.json's last scene: objects[0].center = -1 is invalid; allowed: 3 numbers, one per axis"),
    (_with(AXES, ("scenes", 0, "objects", 0, "center"), [0.0, 1.0]),
     "run.json's last scene: objects[0].center = [0.0, 1.0] is invalid; allowed: 3 numbers, one per axis"),
    (_with(AXES, ("scenes", 0, "objects", 0, "radius"), _GONE), "run.json's last scene: an object the pictures cannot draw"),
])
def test_a_field_in_a_shape_the_pictures_cannot_draw_is_named(document: dict[str, Any], says: str) -> None:
    with pytest.raises(ValueError) as raised:
        check_drawn_fields(document)
    assert str(raised.value).startswith(says), raised.value


def test_plot_of_such_a_folder_is_one_line_exit_2(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "run"
    assert main(["demo", "--out", str(folder), "--duration", "0.02", "--no-plots", "-q"]) == 0
    capsys.readouterr()
    document = json.loads((folder / "run.json").read_text())
    assert "gate_loop" in document and isinstance(document["events"], list)  # what the cases below change
    cases = (("events", None, "run.json's events = None"), ("gate_loop", {"m": "x"}, "run.json's gate_loop.m = 'x'"))
    for key, value, says in cases:
        (folder / "run.json").write_text(json.dumps(document | {key: value}))
        assert main(["plot", str(folder)]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and "Traceback" not in err
        assert err.startswith(f"haptic-bus plot: error: RUN_DIR = '{folder}' is invalid; allowed: a readable run folder "
                              f"({says}"), err
    assert sorted(path.name for path in folder.iterdir()) == ["record.csv", "run.json"]  # nothing drawn


def test_plot_of_a_record_without_a_drawn_column_is_one_line_exit_2(tmp_path: pathlib.Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """record.csv of another version, without a column the pictures draw: one line naming the file and the
    column (it was a KeyError's traceback from timeline_figure); a missing column they do not draw is read
    as before."""
    folder = tmp_path / "run"
    assert main(["demo", "--out", str(folder), "--duration", "0.02", "--no-plots", "-q"]) == 0
    capsys.readouterr()
    lines = (folder / "record.csv").read_text().splitlines()
    names = lines[0].split(",")

    def without(column: str) -> str:
        i = names.index(column)
        return "".join(",".join(fields[:i] + fields[i + 1:]) + "\n" for fields in (line.split(",") for line in lines))

    (folder / "record.csv").write_text(without("position_m"))
    assert main(["plot", str(folder)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == (f"haptic-bus plot: error: RUN_DIR = '{folder}' is invalid; allowed: a readable run folder "
                                 f"({folder / 'record.csv'} has no column position_m; the pictures draw time_s, position_m, "
                                 "force_n, energy_j)\n")
    (folder / "record.csv").write_text(without("layer_n"))  # read as before; drawing it is test_plots' (2.5 s of CPU)
    run = read_run_folder(folder)
    assert run.drawable and run.record is not None and "layer_n" not in run.record.columns
