"""Minimal reader of a profile TOML for the simulated drive (``--profile``).

Only two tables are read: ``[device]`` with any :class:`~sim_drive.parameters.DeviceParameters`
field (``m``, ``b``, ``velocity_per_count``, ``position_per_count``, ``rated_torque`` in N m,
``force_per_torque``, ``max_torque_permille``, ``period``, ``substeps``) and ``[operator]``
(see :func:`sim_drive.operator.operator_from_table`).  Other tables are ignored, so a full
controller profile can be passed as is.  The project's full profile loader replaces this.
"""

from __future__ import annotations

import dataclasses
import pathlib
import tomllib

from haptic_bus.errors import ParameterError
from sim_drive.operator import NoOperator, OperatorModel, operator_from_table
from sim_drive.parameters import DeviceParameters


def load_profile(path: str | pathlib.Path) -> tuple[DeviceParameters, OperatorModel]:
    """The device parameters and operator model a profile file states (defaults where silent)."""
    path = pathlib.Path(path)
    try:
        with open(path, "rb") as handle:
            document = tomllib.load(handle)
    except OSError as exc:
        raise ParameterError("profile", str(path), f"a readable TOML file ({exc.strerror})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError("profile", str(path), f"valid TOML ({exc})") from exc
    device = document.get("device", {})
    operator = document.get("operator")
    if not isinstance(device, dict) or not (operator is None or isinstance(operator, dict)):
        raise ParameterError("profile", str(path), "[device] and [operator] must be tables")
    fields = {f.name for f in dataclasses.fields(DeviceParameters)}
    unknown = sorted(set(device) - fields)
    if unknown:
        raise ParameterError("device", unknown, f"keys among {sorted(fields)}", f"profile {path}")
    parameters = DeviceParameters(**device)
    model = NoOperator() if operator is None else operator_from_table(operator, base=path.parent)
    return parameters, model
