"""The simulated drive's view of an operator profile (``--profile NAME_OR_PATH``): one reader,
:func:`read_simulated_device`, for a one-axis profile (read as one axis) and a profile with ``[[axes]]``.

The same TOML files the controller loads, read by the same readers (:mod:`haptic_bus.profile`),
with the controller's checks and one-line errors.  Each axis is a plant: from ``[device]`` (a
one-axis profile) or ``[axes.device]`` the plant, scaling, velocity model and hidden truth
(``coulomb_friction`` N, ``velocity_noise`` 0x606C counts rms, ``noise_seed``); from ``[loop]``
the ``period`` (s), and from ``[loop]`` or the ``[[axes]]`` table the ``timing`` ("cia402" |
"ideal" | "reception") and ``delay`` (samples; with "reception" the fraction ``delta`` in [0, 1)
after the SYNC at which a target acts).  Who pushes: a one-axis profile's ``[operator_model]``
(the operator on its one handle), a multi-axis profile's ``[space.operator]`` (the hand in space,
:func:`sim_drive.space_operator.hand_from_table`).

Unlike the controller, the drive runs a profile that is silent on some keys (its own defaults,
:class:`DeviceParameters`', fill them: :data:`SILENT`; cia402 timing).  Of a one-axis profile's
controller tables it checks ``[limits]`` and ``[[scene.objects]]`` where given, by the same code
(:mod:`haptic_bus.profile.scene`), and leaves the policies (``[profile]``, ``[gate]``, ``[safety]``,
``[passivity]``, ``[supervisor]``, ``[start]``) to it; a top-level table no profile has is refused.
Of an ``[[axes]]`` table it leaves ``mapping`` and ``force_limit`` to the controller, whose reader
(:mod:`haptic_bus.app.profiles.axes`) validates the whole file.  A bare name is looked up among the
shipped profiles.

A profile the drive runs is its truth; the controller may be given another profile (what it
believes), e.g. without the Coulomb friction or with another velocity model.
"""

from __future__ import annotations

import pathlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from haptic_bus.analysis.loop import PERIOD_RANGE
from haptic_bus.errors import ParameterError
from haptic_bus.profile.device import DeviceTable, check_velocity_period, read_device, read_timing
from haptic_bus.profile.files import resolve_profile
from haptic_bus.profile.link import read_link
from haptic_bus.profile.operator import NO_OPERATOR
from haptic_bus.profile.plant import ONE_AXIS_TABLES, Silent, read_plant
from haptic_bus.profile.reader import Reader, profile_error, read_document
from haptic_bus.profile.scene import read_force_limit, read_scene
from sim_drive.operator import NoOperator, OperatorModel, operator_from_table
from sim_drive.parameters import DEFAULT_RECEPTION_DELAY, DeviceParameters, Timing
from sim_drive.space_operator import SpaceHand, hand_from_table

_DEFAULTS = DeviceParameters()
SILENT = Silent(
    device={"mass": _DEFAULTS.mass, "friction": _DEFAULTS.friction, "friction_source": "the simulated drive's default",
            "velocity_per_count": _DEFAULTS.velocity_per_count, "position_per_count": _DEFAULTS.position_per_count,
            "rated_torque": _DEFAULTS.rated_torque, "force_per_torque": _DEFAULTS.force_per_torque,
            "max_torque_permille": _DEFAULTS.max_torque_permille, "velocity": _DEFAULTS.velocity},
    loop={"period": _DEFAULTS.period, "timing": Timing.CIA402.value, "delay": DEFAULT_RECEPTION_DELAY})
"""What the drive takes where a profile is silent: :class:`DeviceParameters`' defaults, cia402 timing
(a "reception" delay of :data:`DEFAULT_RECEPTION_DELAY` samples)."""
_PROFILE_KEYS = {"period": "loop.period", "reception_delay": "loop.delay"}
"""DeviceParameters field -> the profile key that sets it (where the names differ)."""
_CONTROLLER_KEYS = ("mapping", "force_limit")  # of an [[axes]] table: the controller's business


@dataclass(frozen=True)
class SimAxis:
    """One axis of the simulated device: its ``name`` (``axis0`` for a one-axis profile), CANopen
    ``node_id`` or Modbus ``unit_id`` (None where the profile names none), plant ``parameters`` and
    ``timing``."""

    name: str
    node_id: int | None
    unit_id: int | None
    parameters: DeviceParameters
    timing: Timing


@dataclass(frozen=True)
class SimulatedDevice:
    """The simulated device a profile states, its truth: ``axes`` in coordinate order (one for a
    one-axis profile) and who pushes them: ``operator``, the one-axis profile's ``[operator_model]``
    (None for a profile with ``[[axes]]``), or the hand in space, ``hand`` (the ``[space.operator]``
    table; ``model = "none"`` for a one-axis profile)."""

    path: pathlib.Path
    axes: tuple[SimAxis, ...]
    operator: OperatorModel | None
    hand: Mapping[str, Any]

    @property
    def multi_axis(self) -> bool:
        """True for a profile with ``[[axes]]`` (even of one axis): each axis its own node or unit, the hand in space."""
        return self.operator is None

    def one_axis(self) -> tuple[SimAxis, OperatorModel]:
        """The axis and operator of a one-axis profile; ParameterError for a profile with ``[[axes]]``."""
        if self.operator is None:
            raise profile_error(self.path, "axes", "[[axes]]", "a one-axis profile (a multi-axis profile runs with --node-ids)")
        return self.axes[0], self.operator

    def make_hand(self) -> SpaceHand:
        """A fresh hand in space over every axis of the profile."""
        return hand_from_table(self.hand, len(self.axes))


def read_simulated_device(path_or_name: str | pathlib.Path) -> SimulatedDevice:
    """The axes and who pushes them, as a profile states them (defaults where silent); ParameterError
    naming the file and the key."""
    path = resolve_profile(path_or_name)
    document = read_document(path)
    return _read_axes(path, document) if "axes" in document else _read_one_axis(path, document)


def _read_one_axis(path: pathlib.Path, document: dict[str, Any]) -> SimulatedDevice:
    """A one-axis profile: ``[device]``, ``[loop]`` and ``[operator_model]`` as one axis and its operator."""
    top = Reader(path, "", document)
    top.only(ONE_AXIS_TABLES)  # the controller's tables are its business, a table no profile has is refused
    loop_table = top.table.get("loop")
    if isinstance(loop_table, dict) and "delay" in loop_table and "timing" not in loop_table:
        raise profile_error(path, "loop.delay", loop_table["delay"], "a delay only with [loop] timing")
    plant = read_plant(top, SILENT)
    if "limits" in top.table:  # the controller's tables, checked by the same code (the drive runs neither)
        read_force_limit(path, top.table["limits"], plant.device)
    if "scene" in top.table:
        read_scene(path, top.table["scene"])
    loop = plant.loop
    axis = SimAxis("axis0", None, None, _drive_parameters(path, plant.device, loop.period, loop.timing, loop.delay),
                   Timing(loop.timing))
    operator = NoOperator() if plant.operator_model["model"] == "none" else operator_from_table(plant.operator_model)
    return SimulatedDevice(path, (axis,), operator, NO_OPERATOR)


def _read_axis(path: pathlib.Path, index: int, table: object, period: float) -> SimAxis:
    """One ``[[axes]]`` table: the simulator's part of it (module docstring)."""
    r = Reader(path, f"axes[{index}]", table, silent={"name": f"axis{index}", "timing": Timing.CIA402.value})
    name = r.text("name")
    node, unit = read_link(r)
    timing, delay = read_timing(r)
    device = read_device(path, r.raw("device", "an [axes.device] table", default={}), r.field("device"), SILENT.device)
    r.used.update(_CONTROLLER_KEYS)
    r.done()
    check_velocity_period(path, r.field("device.velocity"), device, period)
    return SimAxis(name, node, unit, _drive_parameters(path, device, period, timing, delay, f"axes[{index}]."), Timing(timing))


def _read_axes(path: pathlib.Path, document: dict[str, Any]) -> SimulatedDevice:
    """A profile with ``[[axes]]``: ``[loop] period``, every axis, and the hand in space."""
    loop = Reader(path, "loop", document.get("loop", {}), SILENT.loop)
    period = loop.real("period", *PERIOD_RANGE, "s")
    tables = document.get("axes")
    if not isinstance(tables, list) or not tables:
        raise profile_error(path, "axes", tables, "an array of tables [[axes]]")
    axes = tuple(_read_axis(path, i, table, period) for i, table in enumerate(tables))
    space = Reader(path, "space", document.get("space", {}))
    hand = space.raw("operator", "a [space.operator] table", default=NO_OPERATOR)
    if not isinstance(hand, Mapping):
        raise profile_error(path, "space.operator", hand, "a TOML table")
    device = SimulatedDevice(path, axes, None, dict(hand))
    try:
        device.make_hand()  # checked now, not at the first SYNC
    except ParameterError as error:
        raise profile_error(path, error.name, error.value, error.allowed) from None
    return device


def _drive_parameters(path: pathlib.Path, device: DeviceTable, period: float, timing: str, delay: float,
                     prefix: str = "") -> DeviceParameters:
    """The simulated drive of ``device`` on a loop of ``period`` s and ``timing``; a value the drive
    cannot take (a "reception" delay of a whole sample or more) is a ParameterError naming the
    profile's key (``prefix`` before it, e.g. ``axes[1].``)."""
    try:
        return DeviceParameters(**device.sim_parameters(period, timing, delay))  # type: ignore[arg-type]
    except ParameterError as error:
        raise profile_error(path, prefix + _PROFILE_KEYS.get(error.name, f"device.{error.name}"), error.value,
                            error.allowed) from None
