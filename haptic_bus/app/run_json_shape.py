"""Whether a run.json holds what the pictures draw, in the shape they draw it (``haptic-bus plot`` of a folder
another version wrote, or one edited by hand): the first field that does not is one ValueError naming it, which
:func:`~haptic_bus.app.run_folder.read_run_folder` turns into one line, exit 2."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from haptic_bus.errors import ParameterError


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _table(field: str, value: object, keys: dict[str, tuple[Callable[[object], bool], str]],
           required: tuple[str, ...] = ()) -> None:
    """ValueError naming ``field.key`` for the first of ``keys`` (key -> test, what it allows) that ``value``
    (a JSON object) holds in another shape, else the first of ``required`` that it lacks."""
    if not isinstance(value, dict):
        raise ValueError(f"run.json's {field} = {_short(value)} is invalid; allowed: a JSON object")
    for key, (test, allowed) in keys.items():
        if key in value and not test(value[key]):
            raise ValueError(f"run.json's {field}.{key} = {_short(value[key])} is invalid; allowed: {allowed}")
    for key in required:
        if key not in value:
            raise ValueError(f"run.json's {field}.{key} is missing")


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _list_of_objects(field: str, value: object) -> list[dict[str, Any]]:
    if not isinstance(value, list) or not all(isinstance(item, dict) for item in value):
        raise ValueError(f"run.json's {field} = {_short(value)} is invalid; allowed: a list of JSON objects")
    return value


_REAL = (_is_real, "a number")
_TEXT: tuple[Callable[[object], bool], str] = (lambda value: isinstance(value, str), "a text")


def check_drawn_fields(document: dict[str, Any]) -> None:
    """ValueError naming the first field the pictures read (the profile's name, the events, the scenes and
    their walls, the loop the gate judged, each axis' name) that ``document`` holds in a shape they cannot
    draw: a run.json another version wrote, or one edited by hand, was a TypeError's or KeyError's traceback
    from deep in the drawing (exit 1), where an unreadable run folder is one line, exit 2.  A field left
    out stays allowed: the pictures draw without it as they did."""
    if "profile" in document:
        _table("profile", document["profile"], {})
    for i, event in enumerate(_list_of_objects("events", document.get("events", []))):
        _table(f"events[{i}]", event, {"time_s": _REAL})
    for i, scene in enumerate(_list_of_objects("scenes", document.get("scenes") or [])):
        _table(f"scenes[{i}]", scene, {"scene_id": (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer"),
                                      "origin": _TEXT})
        _list_of_objects(f"scenes[{i}].objects", scene.get("objects", []))
        for j, wall in enumerate(_list_of_objects(f"scenes[{i}].walls", scene.get("walls", []))):
            _table(f"scenes[{i}].walls[{j}]", wall,
                   {"objects": (lambda v: isinstance(v, list) and all(isinstance(n, str) for n in v), "a list of object names"),
                    "K": _REAL, "B": _REAL, "margin": (lambda v: v is None or _is_real(v), "a number or null")},
                   required=("objects", "K", "B"))
    if "gate_loop" in document:
        _table("gate_loop", document["gate_loop"], {key: _REAL for key in ("m", "b", "T", "delay")} | {"velocity": _TEXT},
               required=("m", "b", "T", "delay", "velocity"))
    if "loop" in document:
        _table("loop", document["loop"], {"period": _REAL})
    settings = document.get("settings", {})
    _table("settings", settings, {})
    for i, axis in enumerate(_list_of_objects("settings.axes", settings.get("axes", []))):
        _table(f"settings.axes[{i}]", axis, {"name": _TEXT}, required=("name",))
    _check_drawn_objects(document, bool(settings.get("axes")))


def _check_drawn_objects(document: dict[str, Any], several_axes: bool) -> None:
    """The scenes' objects built as the pictures build them (a sphere, a wall, ...), each refused in a
    ValueError naming it."""
    from haptic_bus.app.space_records import space_objects
    from haptic_bus.control.scene import object_from_dict

    where = "scenes"
    try:
        if several_axes:
            if document.get("scenes") or "space" in document["settings"]:
                size = len(document["settings"]["axes"])
                scenes = document.get("scenes") or [{"objects": document["settings"]["space"]["objects"]}]
                for j, table in enumerate(_list_of_objects("last scene's objects", scenes[-1]["objects"])):
                    for key in ("center", "point", "normal", "half"):  # a point or direction in the axes' space
                        value = table.get(key)
                        if value is not None and (not isinstance(value, list) or len(value) != size
                                                  or not all(_is_real(x) for x in value)):
                            raise ValueError(f"run.json's last scene: objects[{j}].{key} = {_short(value)} is invalid; "
                                             f"allowed: {size} numbers, one per axis")
                space_objects(document)
            return
        for i, scene in enumerate(document.get("scenes") or []):
            for j, table in enumerate(_list_of_objects(f"scenes[{i}].objects", scene.get("objects", []))):
                where = f"scenes[{i}].objects[{j}]"
                _table(where, table, {"name": _TEXT})
                if "kind" in table:
                    object_from_dict(table)
    except ParameterError as exc:
        raise ValueError(f"run.json's {'last scene' if several_axes else where}: {exc}") from None
    except (KeyError, TypeError, AttributeError, IndexError) as exc:
        what = f"{type(exc).__name__}: {exc}"
        raise ValueError(f"run.json's {'last scene' if several_axes else where}: an object the pictures cannot "
                         f"draw ({what})") from None
