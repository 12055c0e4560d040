"""Which velocity the drive reports (DESIGN 3.5): the measurement model of the sampled loop.

The controller reads a velocity ``y_k`` at every SYNC ``kT``.  Four models of what that number is:

* ``point``: ``y_k = v(kT)``, the velocity at the instant (a tachometer, or a drive that
  estimates velocity far faster than ``T`` and samples it at SYNC) -- the seed's loop;
* ``average``: ``y_k = (x(kT) - x(kT - T)) / T``, the encoder difference over the cycle (most
  servo drives' 0x606C); the wall then is Colgate's position-sampled wall;
* ``window:TW``: ``y_k = (x(kT) - x(kT - TW)) / TW``, the difference over a shorter window
  ``TW`` in ``(0, T]`` (a drive's internal period);
* ``lowpass:TAU``: ``y_k = nu(kT)``, ``TAU dnu/dt = v - nu``, a first-order filter (time
  constant ``TAU`` s) on the velocity before sampling.

Each is a continuous linear filter ``M(s)`` on the velocity followed by the sampler:
``M = 1``, ``(1 - e^{-s TW}) / (s TW)`` (``TW = T`` for ``average``), ``1 / (1 + s TAU)``.
Profiles and the command line spell a model as ``"point"``, ``"average"``,
``"window:0.0005"`` or ``"lowpass:0.002"`` (seconds).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from haptic_bus.errors import ParameterError

KINDS = ("point", "average", "window", "lowpass")
LOWPASS_RANGE = (1e-12, 100.0)  # s: TAU; T/TAU stays finite for every valid T
ALLOWED = (
    "'point', 'average', 'window:SECONDS' (SECONDS in (0, T]) or "
    f"'lowpass:SECONDS' (SECONDS in [{LOWPASS_RANGE[0]:g}, {LOWPASS_RANGE[1]:g}])"
)


@dataclass(frozen=True)
class VelocityModel:
    """What the drive's velocity ``y_k`` is: ``kind`` in :data:`KINDS` and its ``time`` in s.

    ``time`` is the window ``TW`` (``window``), the filter constant ``TAU`` (``lowpass``), and 0
    for ``point`` and ``average`` (whose window is the period itself, known only with ``T``).
    """

    kind: str = "point"
    time: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ParameterError("velocity", self.kind, ALLOWED)
        if self.kind in ("point", "average"):
            if self.time != 0.0:
                raise ParameterError("velocity", f"{self.kind}:{self.time!r}", ALLOWED)
            object.__setattr__(self, "time", 0.0)
            return
        time = self.time
        if isinstance(time, bool) or not isinstance(time, numbers.Real) or not math.isfinite(float(time)):
            raise ParameterError("velocity", f"{self.kind}:{time!r}", ALLOWED)
        time = float(time)
        low, high = (0.0, math.inf) if self.kind == "window" else LOWPASS_RANGE
        if not (low < time <= high if self.kind == "window" else low <= time <= high):
            raise ParameterError("velocity", f"{self.kind}:{time!r}", ALLOWED)
        object.__setattr__(self, "time", time)

    @classmethod
    def parse(cls, text: object) -> VelocityModel:
        """The model a profile or command-line string names (``"window:0.0005"``, ...), else ParameterError."""
        if isinstance(text, VelocityModel):
            return text
        if not isinstance(text, str):
            raise ParameterError("velocity", text, ALLOWED)
        kind, sep, value = text.strip().partition(":")
        kind = kind.strip().lower()
        if kind in ("point", "average"):
            if sep:
                raise ParameterError("velocity", text, ALLOWED)
            return cls(kind)
        if kind not in KINDS or not sep:
            raise ParameterError("velocity", text, ALLOWED)
        try:
            seconds = float(value)
        except ValueError:
            raise ParameterError("velocity", text, ALLOWED) from None
        return cls(kind, seconds)

    def __str__(self) -> str:
        """The profile string: ``point``, ``average``, ``window:0.0005``, ``lowpass:0.002``."""
        return self.kind if self.kind in ("point", "average") else f"{self.kind}:{self.time!r}"

    def window(self, T: float) -> float | None:
        """The differencing window in s (``T`` for ``average``), None for ``point``/``lowpass``."""
        if self.kind == "average":
            return T
        return self.time if self.kind == "window" else None

    def check_period(self, T: float) -> None:
        """Raise ParameterError unless the model fits a loop of period ``T`` s (window ``TW <= T``)."""
        if self.kind == "window" and self.time > T:
            raise ParameterError("velocity", str(self), f"a window in (0, T] = (0, {T:g}] s")


POINT = VelocityModel("point")
