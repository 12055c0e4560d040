"""What the simulated drive reads from an operator profile (``--profile NAME_OR_PATH``).

The same TOML files the controller loads (``profiles/*.toml``, see ``haptic_bus.app.profiles``):
from ``[device]`` the plant and scaling (``mass`` kg, ``friction`` N s/m, ``velocity_per_count``,
``position_per_count``, ``rated_torque`` N m, ``force_per_torque``, ``max_torque_permille``), the
velocity model 0x606C follows (``velocity`` = "point" | "average" | "window:SECONDS" |
"lowpass:SECONDS") and the drive's hidden truth (``coulomb_friction`` N, ``velocity_noise``
0x606C counts rms, ``noise_seed``); from ``[loop]`` the ``period`` (s), the ``timing``
("cia402" | "ideal" | "reception") and ``delay`` (samples: with "reception" the fraction
``delta`` in [0, 1) after the SYNC at which a target acts; with the others, if given, their own
1 or 0); and ``[operator_model]`` (see :func:`sim_drive.operator.operator_from_table`).  The
controller's tables (scene, gate, limits) are not the drive's business and are left to
``haptic_bus``, which validates the whole file; every value read here is still range-checked by
:class:`DeviceParameters`.  A bare name is looked up among the shipped profiles.

A profile the drive runs is its truth; the controller may be given another profile (what it
believes), e.g. without the Coulomb friction or with another velocity model.
"""

from __future__ import annotations

import importlib.resources
import pathlib
import tomllib
from dataclasses import dataclass
from typing import Any

from haptic_bus.errors import ParameterError
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
    "velocity": "velocity",
    "coulomb_friction": "coulomb_friction",
    "velocity_noise": "velocity_noise",
    "noise_seed": "noise_seed",
}
_DESCRIPTIVE = {"friction_source"}
_PROFILE_KEYS = {field: f"device.{key}" for key, field in _DEVICE_FIELDS.items()} | {
    "period": "loop.period",
    "reception_delay": "loop.delay",
}


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
    document = read_toml(path_or_name)
    path = resolve(path_or_name)
    device, loop, operator = (document.get(key, {}) for key in ("device", "loop", "operator_model"))
    for key, table in (("device", device), ("loop", loop), ("operator_model", operator)):
        if not isinstance(table, dict):
            raise ParameterError(key, table, "a TOML table", f"profile {path}")
    parameters, timing = device_parameters(device, loop, f"profile {path}")
    model = operator_from_table(operator, base=path.parent) if operator else NoOperator()
    return DriveProfile(parameters, timing, model)


def read_toml(path_or_name: str | pathlib.Path) -> dict[str, Any]:
    """The TOML document of a profile (a path, or a shipped profile's name); ParameterError if unreadable."""
    path = resolve(path_or_name)
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except OSError as exc:
        allowed = f"a readable TOML file or a shipped profile name ({exc.strerror})"
        raise ParameterError("profile", str(path_or_name), allowed) from exc
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError("profile", str(path), f"valid TOML ({exc})") from exc


def device_parameters(device: dict[str, Any], loop: dict[str, Any], context: str,
                      prefix: str = "") -> tuple[DeviceParameters, Timing | None]:
    """The plant, scaling and hidden truth of a ``[device]`` table, with ``[loop]``'s ``period``,
    ``timing`` and ``delay``; errors name the field as the profile spells it (``prefix`` before it,
    e.g. ``axes[1].``)."""
    unknown = sorted(set(device) - set(_DEVICE_FIELDS) - _DESCRIPTIVE)
    if unknown:
        raise ParameterError(f"{prefix}device.{unknown[0]}", device[unknown[0]], f"keys among {sorted(_DEVICE_FIELDS)}",
                             context)
    fields = {_DEVICE_FIELDS[key]: value for key, value in device.items() if key in _DEVICE_FIELDS}
    if "period" in loop:
        fields["period"] = loop["period"]
    timing = _read_timing(loop, context)
    if timing is Timing.RECEPTION and "delay" in loop:
        fields["reception_delay"] = loop["delay"]
    try:
        return DeviceParameters(**fields), timing
    except ParameterError as exc:  # named as the profile spells it
        raise ParameterError(prefix + _PROFILE_KEYS.get(exc.name, exc.name), exc.value, exc.allowed, context) from None


def _read_timing(loop: dict[str, object], context: str) -> Timing | None:
    """``[loop] timing`` (None if absent); a ``delay`` that contradicts it is a ParameterError."""
    name = loop.get("timing")
    if name is None:
        if "delay" in loop:
            raise ParameterError("loop.delay", loop["delay"], "a delay only with [loop] timing", context)
        return None
    if not isinstance(name, str) or name not in {t.value for t in Timing}:
        raise ParameterError("loop.timing", name, " or ".join(t.value for t in Timing), context)
    timing = Timing(name)
    if timing is not Timing.RECEPTION and "delay" in loop and loop["delay"] != timing.delay:
        allowed = f"{timing.delay:g} samples for timing {name!r} (or leave it out)"
        raise ParameterError("loop.delay", loop["delay"], allowed, context)
    return timing
