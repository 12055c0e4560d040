"""Operator-force models: what the hand on the simulated handle pushes with.

Every model answers ``force(t, position, velocity)`` in N, given the virtual time ``t`` in s
since the drive's first SYNC, the handle position in m and its velocity in m/s.  The drive
holds the answer constant over one plant sub-step (zero-order hold), so the operator's work
``force * displacement`` over a sub-step is exact.

Models are frozen dataclasses whose fields are validated on construction
(:class:`haptic_bus.errors.ParameterError` names the field, its value and the allowed range).
The field order is the parameter order ``p1..p6`` of the manufacturer object 0x2010 (see
:data:`OPERATOR_CODES`).
"""

from __future__ import annotations

import abc
import bisect
import csv
import dataclasses
import math
import os
import pathlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range

FORCE_LIMIT = 1e6  # N: far beyond any haptic handle, keeps every product finite
FREQUENCY_LIMIT = 1e6  # Hz
TIME_LIMIT = 1e9  # s
STIFFNESS_LIMIT = 1e12  # N/m
DAMPING_LIMIT = 1e12  # N s/m
POSITION_LIMIT = 1e6  # m
SPEED_LIMIT = 1e6  # m/s


class Range(NamedTuple):
    """The values a model's field may take: ``low..high`` in ``unit`` (``low`` itself only if ``low_inclusive``)."""

    low: float
    high: float
    unit: str
    low_inclusive: bool = True


class OperatorModel(abc.ABC):
    """A hand on the handle: the force it applies, in N.  Every model is a frozen dataclass; a
    model with numeric fields names itself in ``kind`` and their allowed values in ``ranges``,
    which construction checks."""

    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]  # what makes dataclasses.fields() accept it
    kind: ClassVar[str] = ""
    ranges: ClassVar[Mapping[str, Range]] = {}

    def __post_init__(self) -> None:
        """Each field of ``ranges`` as a float in its range, else ParameterError (naming ``operator KIND``)."""
        for name, (low, high, unit, low_inclusive) in self.ranges.items():
            value = real_in_range(name, getattr(self, name), low, high, low_inclusive=low_inclusive, unit=unit,
                                  context=f"operator {self.kind}")
            object.__setattr__(self, name, value)

    @abc.abstractmethod
    def force(self, t: float, position: float, velocity: float) -> float:
        """Force in N at virtual time ``t`` s, handle ``position`` m, ``velocity`` m/s."""

    def parameters(self) -> tuple[float, ...]:
        """The model's numeric parameters in field order (the ``p1..`` of object 0x2010)."""
        return tuple(float(getattr(self, f.name)) for f in dataclasses.fields(self))


@dataclass(frozen=True)
class NoOperator(OperatorModel):
    """Nobody holds the handle: 0 N."""

    def force(self, t: float, position: float, velocity: float) -> float:
        """Always 0 N."""
        return 0.0


LET_GO = NoOperator()
"""What acts while the drive's torque is off: the hand lets go of an unpowered handle (a simulated
drive takes the operator's force only from its enabling on, as the hand in space does)."""


@dataclass(frozen=True)
class ConstantPush(OperatorModel):
    """A constant push of ``level`` N from t = 0 on."""

    kind: ClassVar[str] = "constant"
    ranges: ClassVar[Mapping[str, Range]] = {"level": Range(-FORCE_LIMIT, FORCE_LIMIT, "N")}

    level: float

    def force(self, t: float, position: float, velocity: float) -> float:
        """``level`` N."""
        return self.level


@dataclass(frozen=True)
class StepPush(OperatorModel):
    """0 N before ``start`` s, ``level`` N from ``start`` on."""

    kind: ClassVar[str] = "step"
    ranges: ClassVar[Mapping[str, Range]] = {"level": Range(-FORCE_LIMIT, FORCE_LIMIT, "N"), "start": Range(0.0, TIME_LIMIT, "s")}

    level: float
    start: float

    def force(self, t: float, position: float, velocity: float) -> float:
        """``level`` N once ``t >= start``, else 0 N."""
        return self.level if t >= self.start else 0.0


@dataclass(frozen=True)
class Sinusoid(OperatorModel):
    """``offset + amplitude sin(2 pi frequency t + phase)`` N (phase in rad)."""

    kind: ClassVar[str] = "sinusoid"
    ranges: ClassVar[Mapping[str, Range]] = {
        "amplitude": Range(0.0, FORCE_LIMIT, "N"), "frequency": Range(0.0, FREQUENCY_LIMIT, "Hz"),
        "phase": Range(-2 * math.pi, 2 * math.pi, "rad"), "offset": Range(-FORCE_LIMIT, FORCE_LIMIT, "N"),
    }

    amplitude: float
    frequency: float
    phase: float = 0.0
    offset: float = 0.0

    def force(self, t: float, position: float, velocity: float) -> float:
        """The sinusoid's value in N at ``t``."""
        return self.offset + self.amplitude * math.sin(2 * math.pi * self.frequency * t + self.phase)


@dataclass(frozen=True)
class Chirp(OperatorModel):
    """Linear chirp ``amplitude sin(2 pi (f0 t + (f1 - f0) t^2 / (2 duration)))`` N on [0, duration], 0 N after."""

    kind: ClassVar[str] = "chirp"
    ranges: ClassVar[Mapping[str, Range]] = {
        "amplitude": Range(0.0, FORCE_LIMIT, "N"), "f0": Range(0.0, FREQUENCY_LIMIT, "Hz"),
        "f1": Range(0.0, FREQUENCY_LIMIT, "Hz"), "duration": Range(0.0, TIME_LIMIT, "s", low_inclusive=False),
    }

    amplitude: float
    f0: float
    f1: float
    duration: float

    def force(self, t: float, position: float, velocity: float) -> float:
        """The chirp's value in N at ``t`` (0 N outside [0, duration])."""
        if not 0.0 <= t <= self.duration:
            return 0.0
        cycles = self.f0 * t + (self.f1 - self.f0) * t * t / (2.0 * self.duration)
        return self.amplitude * math.sin(2 * math.pi * cycles)


@dataclass(frozen=True)
class HandModel(OperatorModel):
    """A hand coupled to the handle by a spring ``stiffness`` N/m and damper ``damping`` N s/m.

    The hand's set-point moves as ``x_s(t) = start + speed t + amplitude sin(2 pi frequency t)``
    (m); the force is ``stiffness (x_s - x) + damping (dx_s/dt - v)`` N.
    """

    kind: ClassVar[str] = "hand"
    ranges: ClassVar[Mapping[str, Range]] = {
        "stiffness": Range(0.0, STIFFNESS_LIMIT, "N/m"), "damping": Range(0.0, DAMPING_LIMIT, "N s/m"),
        "start": Range(-POSITION_LIMIT, POSITION_LIMIT, "m"), "speed": Range(-SPEED_LIMIT, SPEED_LIMIT, "m/s"),
        "amplitude": Range(0.0, POSITION_LIMIT, "m"), "frequency": Range(0.0, FREQUENCY_LIMIT, "Hz"),
    }

    stiffness: float
    damping: float
    start: float = 0.0
    speed: float = 0.0
    amplitude: float = 0.0
    frequency: float = 0.0

    def force(self, t: float, position: float, velocity: float) -> float:
        """Spring-damper force in N between the moving set-point and the handle."""
        omega = 2 * math.pi * self.frequency
        setpoint = self.start + self.speed * t + self.amplitude * math.sin(omega * t)
        setpoint_speed = self.speed + self.amplitude * omega * math.cos(omega * t)
        return self.stiffness * (setpoint - position) + self.damping * (setpoint_speed - velocity)


INTERPOLATIONS = ("hold", "linear")


@dataclass(frozen=True)
class RecordedForce(OperatorModel):
    """A recorded force track: samples ``forces`` (N) at strictly increasing ``times`` (s).

    ``interpolation="hold"`` holds each sample until the next one (zero-order hold);
    ``"linear"`` interpolates linearly between samples.  Before the first sample the force
    is 0 N; after the last sample the last value is held.
    """

    times: tuple[float, ...]
    forces: tuple[float, ...]
    interpolation: str = "hold"

    def __post_init__(self) -> None:
        name = "operator recorded"
        if len(self.times) != len(self.forces) or not self.times:
            raise ParameterError("times/forces", (len(self.times), len(self.forces)),
                                 "two non-empty columns of equal length", name)
        times = tuple(real_in_range("time", t, 0.0, TIME_LIMIT, unit="s", context=name) for t in self.times)
        forces = tuple(real_in_range("force", f, -FORCE_LIMIT, FORCE_LIMIT, unit="N", context=name) for f in self.forces)
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise ParameterError(f"time[{i}]", times[i], f"strictly greater than time[{i - 1}] = {times[i - 1]!r}", name)
        if self.interpolation not in INTERPOLATIONS:
            raise ParameterError("interpolation", self.interpolation, " or ".join(INTERPOLATIONS), name)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "forces", forces)

    @classmethod
    def from_csv(cls, path: str | pathlib.Path, interpolation: str = "hold") -> RecordedForce:
        """Load a CSV with columns time (s) and force (N); a first row without a number in it is a header
        (``time,force``, ``t_s,f_n``: its names are not read).  Rows are counted as in the file, blank ones too."""
        times: list[float] = []
        forces: list[float] = []
        try:
            with open(path, newline="") as file:
                rows = [(line, row) for line, row in enumerate(csv.reader(file), start=1)
                        if row and any(cell.strip() for cell in row)]
        except OSError as exc:
            raise ParameterError("path", str(path), f"a readable CSV file ({exc.strerror})", "operator recorded") from exc
        if rows and not any(_is_number(cell) for cell in rows[0][1]):
            rows = rows[1:]
        for line, row in rows:
            try:
                t, f = (float(cell) for cell in row)
            except ValueError as exc:
                raise ParameterError(f"{path} row {line}", row, "two numbers: time (s), force (N) (a first row "
                                     "without a number is a header)", "operator recorded") from exc
            times.append(t)
            forces.append(f)
        return cls(tuple(times), tuple(forces), interpolation)

    def parameters(self) -> tuple[float, ...]:
        """A recording has no scalar parameters."""
        return ()

    def force(self, t: float, position: float, velocity: float) -> float:
        """The recorded force in N at ``t`` (held or interpolated, see the class docstring)."""
        i = bisect.bisect_right(self.times, t) - 1
        if i < 0:
            return 0.0
        if i == len(self.times) - 1 or self.interpolation == "hold":
            return self.forces[i]
        t0, t1 = self.times[i], self.times[i + 1]
        return self.forces[i] + (self.forces[i + 1] - self.forces[i]) * (t - t0) / (t1 - t0)


# Codes of the manufacturer object 0x2010 sub 1 ("operator model"), and the profile names.
OPERATOR_CODES: dict[int, type[OperatorModel]] = {
    0: NoOperator,
    1: ConstantPush,
    2: StepPush,
    3: Sinusoid,
    4: Chirp,
    5: HandModel,
    6: RecordedForce,
}
OPERATOR_NAMES: dict[str, type[OperatorModel]] = {
    "none": NoOperator,
    "constant": ConstantPush,
    "step": StepPush,
    "sinusoid": Sinusoid,
    "chirp": Chirp,
    "hand": HandModel,
    "recorded": RecordedForce,
}
MAX_OD_PARAMETERS = 6


def operator_code(model: OperatorModel) -> int:
    """The 0x2010 sub 1 code of ``model``'s class."""
    for code, cls in OPERATOR_CODES.items():
        if type(model) is cls:
            return code
    raise ParameterError("operator", type(model).__name__, "one of the built-in operator models")


def operator_from_code(code: int, parameters: Sequence[float]) -> OperatorModel:
    """Build the model with 0x2010 ``code`` from ``parameters`` p1..p6 (extra ones ignored)."""
    cls = OPERATOR_CODES.get(code)
    if cls is None or cls is RecordedForce:
        allowed = ", ".join(f"{c} ({k.__name__})" for c, k in OPERATOR_CODES.items() if k is not RecordedForce)
        raise ParameterError("operator model code", code, allowed + "; a recording is loaded from a profile only")
    count = len(dataclasses.fields(cls))
    return cls(*parameters[:count])


def operator_from_table(table: Mapping[str, Any], base: pathlib.Path | None = None) -> OperatorModel:
    """Build a model from a profile's ``[operator]`` table: ``model = "<name>"`` plus its fields.

    ``recorded`` takes ``path`` (relative to ``base``) and ``interpolation``.
    """
    params = dict(table)
    name = params.pop("model", "none")
    cls = OPERATOR_NAMES.get(name) if isinstance(name, str) else None
    if cls is None:
        raise ParameterError("operator.model", name, ", ".join(OPERATOR_NAMES), "profile")
    if cls is RecordedForce:
        path = params.pop("path", None)
        if not isinstance(path, str):
            raise ParameterError("operator.path", path, "a CSV file path (string)", "profile")
        interpolation = params.pop("interpolation", "hold")
        if params:
            raise ParameterError("operator", sorted(params), "only model, path, interpolation for a recording", "profile")
        resolved = pathlib.Path(path) if base is None else base / path
        return RecordedForce.from_csv(resolved, interpolation)
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(params) - fields)
    if unknown:
        raise ParameterError("operator", unknown, f"fields of {name}: {sorted(fields) or 'none'}", "profile")
    try:
        return cls(**params)
    except TypeError as exc:
        raise ParameterError("operator", sorted(params), f"all required fields of {name}: {sorted(fields)}", "profile") from exc


def operator_usage() -> str:
    """Every spelled form :func:`operator_from_spec` takes, ``" | "``-separated (optional fields in brackets)."""
    forms = []
    for name, cls in OPERATOR_NAMES.items():
        if cls is RecordedForce:
            forms.append(f"{name}:CSV[,{'|'.join(INTERPOLATIONS)}]")
            continue
        fields = dataclasses.fields(cls)
        required = [f.name for f in fields if f.default is dataclasses.MISSING]
        optional = [f.name for f in fields if f.default is not dataclasses.MISSING]
        text = ",".join(required) + (f"[,{','.join(optional)}]" if optional else "")
        forms.append(f"{name}:{text}" if text else name)
    return " | ".join(forms)


def _is_number(text: str) -> bool:
    """Whether ``text`` reads as a float (``nan`` and ``inf`` too: a value, refused later by its range)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def operator_from_spec(spec: str) -> OperatorModel:
    """The model a command line spells ``NAME[:V1,V2,...]``: the values are the model's fields in
    order (:func:`operator_usage`; SI units: N, s, Hz, rad, m, N/m, N s/m), trailing optional ones
    may be left out; ``recorded:CSV[,hold|linear]`` loads a force track (columns time s, force N).
    ParameterError (named ``--operator``) for anything else."""
    name, _, values = spec.partition(":")
    cls = OPERATOR_NAMES.get(name.strip())
    allowed = operator_usage()
    if cls is None:
        raise ParameterError("--operator", spec, allowed)
    if cls is RecordedForce:
        path, _, interpolation = values.rpartition(",")
        if path and interpolation not in INTERPOLATIONS and os.path.isfile(path) and not os.path.exists(values):
            raise ParameterError("interpolation", interpolation, " or ".join(INTERPOLATIONS), "--operator recorded")
        if interpolation not in INTERPOLATIONS:  # no interpolation named: the comma, if any, is the path's
            path, interpolation = values, "hold"
        if not path:
            raise ParameterError("--operator", spec, allowed)
        return RecordedForce.from_csv(path, interpolation)
    fields = dataclasses.fields(cls)
    required = sum(f.default is dataclasses.MISSING for f in fields)
    texts = [text.strip() for text in values.split(",")] if values else []
    try:
        numbers = [float(text) for text in texts]
    except ValueError:
        raise ParameterError("--operator", spec, allowed) from None
    if not required <= len(numbers) <= len(fields):
        raise ParameterError("--operator", spec, allowed)
    try:
        return cls(*numbers)
    except ParameterError as exc:  # a field out of its range, named as the command line spells it
        raise ParameterError(exc.name, exc.value, exc.allowed, f"--operator {name}") from None
