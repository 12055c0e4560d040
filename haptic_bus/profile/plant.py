"""The part of a one-axis profile both the controller and the simulated drive read, read once.

:func:`read_plant` reads ``[device]``, ``[loop]``, ``[operator_model]`` and ``[identification]``
of a profile's document and checks them together (the velocity model against the period; the
declared device against what was measured).  The controller's view
(:func:`haptic_bus.app.profiles.one_axis.read_one_axis`) adds its own tables (limits, gate, scene, policies);
the simulated drive's view (:func:`sim_drive.profile.read_simulated_device`) builds its plant and operator
from the same :class:`PlantTables`, with its own defaults where the file is silent.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from haptic_bus.profile.device import DeviceTable, LoopTiming, check_velocity_period, read_device, read_loop
from haptic_bus.profile.identification import IdentifiedDevice, check_against_identification, read_identification
from haptic_bus.profile.operator import read_operator_model
from haptic_bus.profile.reader import REQUIRED, Reader

ONE_AXIS_TABLES = ("profile", "device", "loop", "limits", "gate", "scene", "operator_model", "safety", "passivity",
                   "supervisor", "start", "identification")
"""Every top-level table of a one-axis profile."""


@dataclass(frozen=True)
class Silent:
    """Defaults for keys a reader lets be left out: ``device`` and ``loop`` (key -> value); with
    them a missing ``[device]`` or ``[loop]`` table reads as empty."""

    device: Mapping[str, object] = field(default_factory=dict)
    loop: Mapping[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class PlantTables:
    """The plant tables of a one-axis profile, checked together: the handle and its drive (``[device]``),
    the loop (``[loop]``), the simulated operator (``[operator_model]``) and what identification measured
    (``[identification]``, None when absent)."""

    device: DeviceTable
    loop: LoopTiming
    operator_model: Mapping[str, Any] = field(hash=False)
    identification: IdentifiedDevice | None


def read_plant(top: Reader, silent: Silent | None = None) -> PlantTables:
    """The plant tables of the document ``top`` reads (each marked used); ``silent``: the simulated
    drive's defaults (None: every key is required, as the controller reads)."""
    path, empty = top.path, REQUIRED if silent is None else {}
    device = read_device(path, top.raw("device", "a [device] table", default=empty),
                         silent=None if silent is None else silent.device)
    loop = read_loop(path, top.raw("loop", "a [loop] table", default=empty), None if silent is None else silent.loop)
    operator_model = read_operator_model(path, top.raw("operator_model", "", default=None))
    identification = read_identification(path, top.raw("identification", "an [identification] table", default=None))
    if identification is not None:
        check_against_identification(path, device, loop, identification)
    check_velocity_period(path, "device.velocity", device, loop.period)
    return PlantTables(device, loop, operator_model, identification)
