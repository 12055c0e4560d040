"""The simulated drive's view of an operator profile (``--profile NAME_OR_PATH``).

The same TOML files the controller loads, read by the same reader
(:func:`haptic_bus.profile.plant.read_plant`): from ``[device]`` the plant, scaling, velocity
model and hidden truth (``coulomb_friction`` N, ``velocity_noise`` 0x606C counts rms,
``noise_seed``); from ``[loop]`` the ``period`` (s), the ``timing`` ("cia402" | "ideal" |
"reception") and ``delay`` (samples; with "reception" the fraction ``delta`` in [0, 1) after the
SYNC at which a target acts); and ``[operator_model]``.  The checks and the one-line errors are
the controller's.  Unlike the controller, the drive runs a profile that is silent on some keys
(its own defaults, :class:`DeviceParameters`', fill them); of the controller's tables it checks
``[limits]`` and ``[[scene.objects]]`` where given, by the same code
(:mod:`haptic_bus.profile.scene`), and leaves the policies (``[profile]``, ``[gate]``, ``[safety]``,
``[passivity]``, ``[supervisor]``, ``[start]``) to it; a top-level table no profile has is refused.  A
bare name is looked up among the shipped profiles.

A profile the drive runs is its truth; the controller may be given another profile (what it
believes), e.g. without the Coulomb friction or with another velocity model.
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass

from haptic_bus.errors import ParameterError
from haptic_bus.profile.device import DeviceTable
from haptic_bus.profile.files import resolve_profile
from haptic_bus.profile.plant import ONE_AXIS_TABLES, Silent, read_plant
from haptic_bus.profile.reader import Reader, profile_error, read_document
from haptic_bus.profile.scene import read_force_limit, read_scene
from sim_drive.operator import NoOperator, OperatorModel, operator_from_table
from sim_drive.parameters import DEFAULT_RECEPTION_DELAY, DeviceParameters, Timing

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


@dataclass(frozen=True)
class DriveProfile:
    """The drive's side of a profile: plant and scaling, timing (None: the profile names none), operator."""

    parameters: DeviceParameters
    timing: Timing | None
    operator: OperatorModel


def load_profile(path_or_name: str | pathlib.Path) -> DriveProfile:
    """The device parameters, timing and operator model a profile states (defaults where silent);
    ParameterError naming the file and the key."""
    path = resolve_profile(path_or_name)
    top = Reader(path, "", read_document(path))
    if "axes" in top.table:
        raise profile_error(path, "axes", "[[axes]]", "a one-axis profile (a multi-axis profile runs with --node-ids)")
    top.only(ONE_AXIS_TABLES)  # the controller's tables are its business, a table no profile has is refused
    loop_table = top.table.get("loop")
    if isinstance(loop_table, dict) and "delay" in loop_table and "timing" not in loop_table:
        raise profile_error(path, "loop.delay", loop_table["delay"], "a delay only with [loop] timing")
    plant = read_plant(top, SILENT)
    if "limits" in top.table:  # the controller's tables, checked by the same code (the drive runs neither)
        read_force_limit(path, top.table["limits"], plant.device)
    if "scene" in top.table:
        read_scene(path, top.table["scene"])
    timing = Timing(plant.loop.timing) if isinstance(loop_table, dict) and "timing" in loop_table else None
    parameters = drive_parameters(path, plant.device, plant.loop.period, plant.loop.timing, plant.loop.delay)
    operator = NoOperator() if plant.operator_model["model"] == "none" else operator_from_table(plant.operator_model)
    return DriveProfile(parameters, timing, operator)


def drive_parameters(path: pathlib.Path, device: DeviceTable, period: float, timing: str, delay: float,
                     prefix: str = "") -> DeviceParameters:
    """The simulated drive of ``device`` on a loop of ``period`` s and ``timing``; a value the drive
    cannot take (a "reception" delay of a whole sample or more) is a ParameterError naming the
    profile's key (``prefix`` before it, e.g. ``axes[1].``)."""
    try:
        return DeviceParameters(**device.sim_parameters(period, timing, delay))  # type: ignore[arg-type]
    except ParameterError as error:
        raise profile_error(path, prefix + _PROFILE_KEYS.get(error.name, f"device.{error.name}"), error.value,
                            error.allowed) from None
