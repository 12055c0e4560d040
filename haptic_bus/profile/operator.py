"""``[operator_model]``: the simulated operator of a demo, checked here and built by the simulator
(:func:`sim_drive.operator.operator_from_table` takes the checked table).

``model`` = none | constant | step | sinusoid | chirp | hand | recorded (alias ``csv``) plus that
model's fields; ``recorded`` takes ``path`` (a CSV of time s, force N, relative to the profile)
and ``interpolation`` ("hold" or "linear").
"""

from __future__ import annotations

import math
import pathlib
import types
from collections.abc import Mapping
from typing import Any

from haptic_bus.profile.reader import REQUIRED, Reader, profile_error

# Operator models, aligned with sim_drive.operator (field -> (low, high, unit, default or
# REQUIRED)); haptic_bus does not import sim_drive (dependencies point the other way).
_F, _HZ, _T = (-1e6, 1e6, "N"), (0.0, 1e6, "Hz"), (0.0, 1e9, "s")
OPERATOR_FIELDS: dict[str, dict[str, tuple]] = {
    "none": {},
    "constant": {"level": (*_F, REQUIRED)},
    "step": {"level": (*_F, REQUIRED), "start": (*_T, REQUIRED)},
    "sinusoid": {"amplitude": (0.0, 1e6, "N", REQUIRED), "frequency": (*_HZ, REQUIRED),
                 "phase": (-2 * math.pi, 2 * math.pi, "rad", 0.0), "offset": (*_F, 0.0)},
    "chirp": {"amplitude": (0.0, 1e6, "N", REQUIRED), "f0": (*_HZ, REQUIRED), "f1": (*_HZ, REQUIRED),
              "duration": (0.0, 1e9, "s", REQUIRED)},
    "hand": {"stiffness": (0.0, 1e12, "N/m", REQUIRED), "damping": (0.0, 1e12, "N s/m", REQUIRED),
             "start": (-1e6, 1e6, "m", 0.0), "speed": (-1e6, 1e6, "m/s", 0.0),
             "amplitude": (0.0, 1e6, "m", 0.0), "frequency": (*_HZ, 0.0)},
    "recorded": {},  # path (CSV: time s, force N) and interpolation, checked apart
}
OPERATOR_ALIASES = {"csv": "recorded"}
INTERPOLATIONS = ("hold", "linear")
NO_OPERATOR: Mapping[str, Any] = types.MappingProxyType({"model": "none"})


def read_operator_model(path: pathlib.Path, table: object) -> Mapping[str, Any]:
    """The checked ``[operator_model]`` (``table`` None when absent: no operator); a recording's
    ``path`` made absolute."""
    if table is None:
        return NO_OPERATOR
    r = Reader(path, "operator_model", table)
    names = tuple(OPERATOR_FIELDS) + tuple(OPERATOR_ALIASES)
    model = OPERATOR_ALIASES.get(name := r.text("model", choices=names), name)
    out: dict[str, Any] = {"model": model}
    if model == "recorded":
        given = r.text("path")
        csv = (path.parent / given).resolve()
        if not csv.is_file():
            raise profile_error(path, "operator_model.path", given,
                                f"a CSV file (time s, force N), relative to {path.parent}")
        out["path"] = str(csv)
        out["interpolation"] = r.text("interpolation", choices=INTERPOLATIONS, default="hold")
    for key, (low, high, unit, default) in OPERATOR_FIELDS[model].items():
        low_inclusive = not (model == "chirp" and key == "duration")
        out[key] = r.real(key, low, high, unit, low_inclusive=low_inclusive, default=default)
    r.done()
    return types.MappingProxyType(out)
