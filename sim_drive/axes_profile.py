"""What the simulated multi-axis device reads from a multi-axis profile (``[[axes]]``).

The same TOML files the controller loads (``haptic_bus.app.axes_profile`` validates the whole
file), read with the same readers (:mod:`haptic_bus.profile`); the simulator reads its part:
``[loop] period``, and per ``[[axes]]`` table the ``name``, ``node_id`` or ``unit_id``, ``timing``/``delay``
and ``[axes.device]`` (plant, scaling and hidden truth, as :func:`sim_drive.profile.load_profile`
reads a one-axis ``[device]``, with the same defaults where it is silent), and the hand in space
``[space.operator]`` (:func:`sim_drive.space_operator.hand_from_table`).
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from drives.cia301 import NODE_ID_RANGE
from drives.modbus.register_map import UNIT_ID_RANGE
from haptic_bus.analysis.loop import PERIOD_RANGE
from haptic_bus.errors import ParameterError
from haptic_bus.profile.device import check_velocity_period, read_device, read_timing
from haptic_bus.profile.files import resolve_profile
from haptic_bus.profile.reader import Reader, profile_error, read_document
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import SILENT, drive_parameters
from sim_drive.space_operator import SpaceHand, hand_from_table

_CONTROLLER_KEYS = ("mapping", "force_limit")  # of an [[axes]] table: the controller's business


@dataclass(frozen=True)
class SimAxis:
    """One axis of the simulated device: its ``name``, CANopen ``node_id`` or Modbus ``unit_id`` (the
    other None), plant ``parameters`` and ``timing``."""

    name: str
    node_id: int | None
    unit_id: int | None
    parameters: DeviceParameters
    timing: Timing


@dataclass(frozen=True)
class AxesDeviceProfile:
    """The simulated device's side of a multi-axis profile: its axes (coordinate order) and the hand's table."""

    axes: tuple[SimAxis, ...]
    hand: Mapping[str, Any]

    def make_hand(self) -> SpaceHand:
        """A fresh hand in space over every axis of the profile."""
        return hand_from_table(self.hand, len(self.axes))


def is_axes_profile(path_or_name: str | pathlib.Path) -> bool:
    """True for a profile with an ``[[axes]]`` array."""
    return "axes" in read_document(resolve_profile(path_or_name))


def _read_axis(path: pathlib.Path, index: int, table: object, period: float) -> SimAxis:
    r = Reader(path, f"axes[{index}]", table, silent={"name": f"axis{index}", "timing": Timing.CIA402.value})
    name = r.text("name")
    node = r.whole("node_id", *NODE_ID_RANGE) if "node_id" in r.table else None
    unit = r.whole("unit_id", *UNIT_ID_RANGE) if "unit_id" in r.table else None
    r.used.update(("node_id", "unit_id"))  # exactly one of them: the controller's profile checks it
    timing, delay = read_timing(r)
    device = read_device(path, r.raw("device", "an [axes.device] table", default={}), r.field("device"), SILENT.device)
    r.used.update(_CONTROLLER_KEYS)
    r.done()
    check_velocity_period(path, r.field("device.velocity"), device, period)
    return SimAxis(name, node, unit, drive_parameters(path, device, period, timing, delay, f"axes[{index}]."), Timing(timing))


def load_axes_device(path_or_name: str | pathlib.Path) -> AxesDeviceProfile:
    """The axes and the hand a multi-axis profile states; ParameterError naming the field."""
    path = resolve_profile(path_or_name)
    document = read_document(path)
    loop = Reader(path, "loop", document.get("loop", {}), SILENT.loop)
    period = loop.real("period", *PERIOD_RANGE, "s")
    tables = document.get("axes")
    if not isinstance(tables, list) or not tables:
        raise profile_error(path, "axes", tables, "an array of tables [[axes]]")
    axes = tuple(_read_axis(path, i, table, period) for i, table in enumerate(tables))
    space = Reader(path, "space", document.get("space", {}))
    hand = space.raw("operator", "a [space.operator] table", default={"model": "none"})
    if not isinstance(hand, dict):
        raise profile_error(path, "space.operator", hand, "a TOML table")
    profile = AxesDeviceProfile(axes, dict(hand))
    try:
        profile.make_hand()  # checked now, not at the first SYNC
    except ParameterError as error:
        raise profile_error(path, error.name, error.value, error.allowed) from None
    return profile
