"""What the simulated drive reads from an operator profile (``--profile NAME_OR_PATH``).

The same TOML files the controller loads (``profiles/*.toml``, see ``haptic_bus.app.profiles``):
from ``[device]`` the plant and scaling (``mass`` kg, ``friction`` N s/m, ``velocity_per_count``,
``position_per_count``, ``rated_torque`` N m, ``force_per_torque``, ``max_torque_permille``),
from ``[loop]`` the ``period`` (s) and ``timing``, and ``[operator_model]`` (see
:func:`sim_drive.operator.operator_from_table`).  The controller's tables (scene, gate,
limits) are not the drive's business and are left to ``haptic_bus``, which validates the
whole file; every value read here is still range-checked by :class:`DeviceParameters`.
A bare name is looked up among the shipped profiles.
"""

from __future__ import annotations

import importlib.resources
import pathlib
import tomllib
from dataclasses import dataclass

from drives.errors import ParameterError
from sim_drive.operator import NoOperator, OperatorModel, operator_from_table
from sim_drive.parameters import DeviceParameters, Timing

_DEVICE_FIELDS = {  # profile key -> DeviceParameters field
    "mass": "m",
    "friction": "b",
    "velocity_per_count": "velocity_per_count",
    "position_per_count": "position_per_count",
    "rated_torque": "rated_torque",
    "force_per_torque": "force_per_torque",
    "max_torque_permille": "max_torque_permille",
}
_DESCRIPTIVE = {"friction_source"}


@dataclass(frozen=True)
class DriveProfile:
    """The drive's side of a profile: plant and scaling, timing, operator."""

    parameters: DeviceParameters
    timing: Timing | None
    operator: OperatorModel


def resolve(path_or_name: str | pathlib.Path) -> pathlib.Path:
    """A path as given, or the shipped profile ``profiles/<name>.toml``."""
    path = pathlib.Path(path_or_name)
    if path.suffix == ".toml" or path.exists():
        return path
    return pathlib.Path(str(importlib.resources.files("profiles") / f"{path_or_name}.toml"))


def load_profile(path_or_name: str | pathlib.Path) -> DriveProfile:
    """The device parameters, timing and operator model a profile states (defaults where silent)."""
    path = resolve(path_or_name)
    try:
        with open(path, "rb") as handle:
            document = tomllib.load(handle)
    except OSError as exc:
        raise ParameterError("profile", str(path_or_name), f"a readable TOML file or a shipped profile name ({exc.strerror})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError("profile", str(path), f"valid TOML ({exc})") from exc
    device, loop, operator = (document.get(key, {}) for key in ("device", "loop", "operator_model"))
    for key, table in (("device", device), ("loop", loop), ("operator_model", operator)):
        if not isinstance(table, dict):
            raise ParameterError(key, table, "a TOML table", f"profile {path}")
    unknown = sorted(set(device) - set(_DEVICE_FIELDS) - _DESCRIPTIVE)
    if unknown:
        raise ParameterError(f"device.{unknown[0]}", device[unknown[0]], f"keys among {sorted(_DEVICE_FIELDS)}", f"profile {path}")
    fields = {_DEVICE_FIELDS[key]: value for key, value in device.items() if key in _DEVICE_FIELDS}
    if "period" in loop:
        fields["period"] = loop["period"]
    timing = loop.get("timing")
    if timing is not None and timing not in {t.value for t in Timing}:
        raise ParameterError("loop.timing", timing, " or ".join(t.value for t in Timing), f"profile {path}")
    model = operator_from_table(operator, base=path.parent) if operator else NoOperator()
    return DriveProfile(DeviceParameters(**fields), None if timing is None else Timing(timing), model)
