"""The controller's ``[limits]`` and ``[[scene.objects]]`` of a one-axis profile, checked here so the
simulated drive refuses the same mistakes with the same line (it runs neither; the controller
builds its scene from what :func:`read_scene` returns, :mod:`haptic_bus.app.profiles.one_axis`).
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass

from haptic_bus.analysis.loop import DAMPING_RANGE, STIFFNESS_RANGE
from haptic_bus.errors import ParameterError
from haptic_bus.profile.device import DeviceTable
from haptic_bus.profile.reader import NAME_PATTERN, Reader, profile_error, refuse_duplicates
from haptic_bus.validation import real_in_range

POSITION_RANGE = (-1e6, 1e6)  # m, as haptic_bus.control.scene
FORCE_RANGE = (0.0, 1e6)  # N, exclusive low
OBJECT_KINDS = ("wall", "slot", "detent")


@dataclass(frozen=True)
class ObjectTable:
    """One checked ``[[scene.objects]]`` table: ``kind``, ``name``, ``stiffness`` N/m, ``damping`` N s/m and
    ``where``, the kind's placement: wall (position m, normal -1 | +1), slot (low m, high m), detent
    (center m, reach m)."""

    kind: str
    name: str
    stiffness: float
    damping: float
    where: tuple[float, float]


def _read_object(path: pathlib.Path, index: int, table: object) -> ObjectTable:
    r = Reader(path, f"scene.objects[{index}]", table)
    kind = r.text("kind", choices=OBJECT_KINDS)
    name = r.text("name", pattern=NAME_PATTERN)
    stiffness = r.real("stiffness", *STIFFNESS_RANGE, "N/m")
    damping = r.real("damping", *DAMPING_RANGE, "N s/m")
    if kind == "wall":
        position = r.real("position", *POSITION_RANGE, "m")
        normal = r.raw("normal", "-1 (solid above position, pushed into in +x) or +1 (solid below)")
        if isinstance(normal, bool) or normal not in (-1, 1):
            raise profile_error(path, r.field("normal"), normal, "-1 (solid above position) or +1 (solid below)")
        where = (position, -1.0 if normal == -1 else 1.0)
    elif kind == "slot":
        low = r.real("low", *POSITION_RANGE, "m")
        high = r.real("high", *POSITION_RANGE, "m")
        if not high > low:
            raise profile_error(path, r.field("high"), high, f"greater than low = {low:g} m")
        where = (low, high)
    else:
        where = (r.real("center", *POSITION_RANGE, "m"), r.real("reach", 0.0, 1e6, "m", low_inclusive=False))
    r.done()
    return ObjectTable(kind, name, stiffness, damping, where)


def read_scene(path: pathlib.Path, table: object) -> tuple[ObjectTable, ...]:
    """``[scene]``: its ``[[scene.objects]]`` checked (types, ranges, unique names); ParameterError naming the field."""
    r = Reader(path, "scene", table)
    objects = r.raw("objects", "an array of tables [[scene.objects]] (may be empty)", default=[])
    if not isinstance(objects, list):
        raise profile_error(path, "scene.objects", objects, "an array of tables [[scene.objects]]")
    r.done()
    scene = tuple(_read_object(path, i, obj) for i, obj in enumerate(objects))
    refuse_duplicates(path, "scene.objects", "name", [obj.name for obj in scene])
    return scene


def read_force_limit(path: pathlib.Path, table: object, device: DeviceTable) -> float:
    """``[limits] force_limit`` in N: in (0, what the device's 0x6072 allows]; ParameterError otherwise."""
    limits = Reader(path, "limits", table)
    force_limit = limits.real("force_limit", *FORCE_RANGE, "N", low_inclusive=False)
    limits.done()
    return check_force_limit("limits.force_limit", force_limit, device, f"profile {path}")


def check_force_limit(field: str, value: object, device: DeviceTable, context: str) -> float:
    """A force limit in N: a finite real in (0, what the device's 0x6072 allows]; ParameterError naming ``field``
    otherwise.  The profile readers check it, and a run checks it again for a profile a program built
    (``dataclasses.replace``), which no reader saw."""
    force_limit = real_in_range(field, value, *FORCE_RANGE, low_inclusive=False, unit="N", context=context)
    if force_limit > device.max_force * (1 + 1e-12):
        raise ParameterError(
            field, force_limit,
            f"(0, {device.max_force:g}] N, the force 0x6072 allows: max_torque_permille {device.max_torque_permille}"
            f" * rated_torque {device.rated_torque:g} N m * force_per_torque {device.force_per_torque:g} N/(N m) / 1000",
            context)
    return force_limit
