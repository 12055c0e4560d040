"""What the simulated multi-axis device reads from a multi-axis profile (``[[axes]]``).

The same TOML files the controller loads (``haptic_bus.app.axes_profile`` validates the whole
file); the simulator reads its part: ``[loop] period``, and per ``[[axes]]`` table the ``name``,
``node_id``, ``timing``/``delay`` and ``[axes.device]`` (plant, scaling and hidden truth, as
:func:`sim_drive.profile.device_parameters` reads a one-axis ``[device]``), and the hand in
space ``[space.operator]`` (:func:`sim_drive.space_operator.hand_from_table`).
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from haptic_bus.errors import ParameterError
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import device_parameters, read_toml, resolve
from sim_drive.space_operator import SpaceHand, hand_from_table


@dataclass(frozen=True)
class SimAxis:
    """One axis of the simulated device: its ``name``, CANopen ``node_id``, plant ``parameters`` and ``timing``."""

    name: str
    node_id: int
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
    return "axes" in read_toml(path_or_name)


def _table(value: object, name: str, context: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ParameterError(name, value, "a TOML table", context)
    return value


def load_axes_device(path_or_name: str | pathlib.Path) -> AxesDeviceProfile:
    """The axes and the hand a multi-axis profile states; ParameterError naming the field."""
    document = read_toml(path_or_name)
    context = f"profile {resolve(path_or_name)}"
    loop = _table(document.get("loop", {}), "loop", context)
    tables = document.get("axes")
    if not isinstance(tables, list) or not tables:
        raise ParameterError("axes", tables, "an array of tables [[axes]]", context)
    axes = []
    for i, table in enumerate(tables):
        table = _table(table, f"axes[{i}]", context)
        node = table.get("node_id")
        if not isinstance(node, int) or isinstance(node, bool) or not 1 <= node <= 127:
            raise ParameterError(f"axes[{i}].node_id", node, "a CANopen node id 1..127", context)
        axis_loop = {"period": loop["period"]} if "period" in loop else {}
        axis_loop.update({key: table[key] for key in ("timing", "delay") if key in table})
        device = _table(table.get("device", {}), f"axes[{i}].device", context)
        parameters, timing = device_parameters(device, axis_loop, context, prefix=f"axes[{i}].")
        axes.append(SimAxis(str(table.get("name", f"axis{i}")), node, parameters, timing or Timing.CIA402))
    space = _table(document.get("space", {}), "space", context)
    hand = _table(space.get("operator", {"model": "none"}), "space.operator", context)
    profile = AxesDeviceProfile(tuple(axes), dict(hand))
    profile.make_hand()  # checked now, not at the first SYNC
    return profile
