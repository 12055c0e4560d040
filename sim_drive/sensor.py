"""What the simulated drive measures at each SYNC: 0x606C velocity and 0x6064 position, in counts.

0x606C is the velocity the drive's :class:`~haptic_bus.analysis.velocity.VelocityModel` defines
(exactly as the analysis does, DESIGN 3.5), at SYNC ``kT``:

* ``point``: ``v(kT)``;
* ``average``: ``(x(kT) - x(kT - T)) / T``; ``window:TW``: ``(x(kT) - x(kT - TW)) / TW``, the
  displacement summed over the exact pieces since the window's start (:class:`WindowMeter`);
* ``lowpass:TAU``: ``nu(kT)`` with ``TAU dnu/dt = v - nu``, integrated exactly over every
  stretch of held force (:class:`LowpassMeter`).

Before the first SYNC the handle was at rest, so the first sample of a window is 0 and the
filter starts at 0.  Then the drive's hidden noise (``velocity_noise`` counts rms, zero-mean
Gaussian, from a generator seeded with ``noise_seed``) is added, and velocity and position are
quantised to counts (``velocity_per_count`` m/s, ``position_per_count`` m per count): rounded,
saturated at INTEGER32, never wrapped.
"""

from __future__ import annotations

import math
import random
from typing import TYPE_CHECKING

from haptic_bus.analysis.plant import exp_divided_difference
from sim_drive.handle import Handle, Meter
from sim_drive.parameters import DeviceParameters

if TYPE_CHECKING:
    from sim_drive.transmission import TwoMassHandle

INT32_RANGE = (-(1 << 31), (1 << 31) - 1)
_LOW, _HIGH = INT32_RANGE


def saturate(value: int, low: int, high: int) -> int:
    """``value`` clipped to ``[low, high]`` (saturate, never wrap)."""
    return low if value < low else high if value > high else value


class WindowMeter:
    """``(x(kT) - x(kT - TW)) / TW`` in m/s: the displacement since the window's start, over ``TW`` s."""

    def __init__(self, width: float, period: float) -> None:
        self.window = min(width / period, 1.0)  # TW/T: the handle restarts the sum at 1 - TW/T of the period
        self._width = width
        self._displacement = 0.0

    def coefficients(self, h: float) -> tuple[float, ...]:
        """None needed: a displacement is summed as it is."""
        return ()

    def restart(self) -> None:
        """The window starts: nothing moved in it yet."""
        self._displacement = 0.0

    def track(self, coefficients: tuple[float, ...], v0: float, net: float, dx: float) -> None:
        """Add the stretch's displacement ``dx`` (m)."""
        self._displacement += dx

    def value(self) -> float:
        """The velocity over the window, m/s."""
        return self._displacement / self._width


class LowpassMeter:
    """``nu`` in m/s, ``TAU dnu/dt = v - nu``: a first-order filter on the handle's velocity.

    Over a stretch of ``h`` s with ``v(0) = v0`` and the net force ``f`` held on ``m dv/dt + b v = f``
    (``lambda = 1/TAU``, ``beta = b/m``)::

        nu(h) = e^{-lambda h} nu + lambda h exp[-lambda h, -beta h] v0 + (lambda h^2 / m) exp[-lambda h, -beta h, 0] f

    (divided differences of ``exp``, :func:`~haptic_bus.analysis.plant.exp_divided_difference`):
    positive terms, exact for ``TAU`` of any size against ``h`` and ``m/b``.
    """

    window = None

    def __init__(self, tau: float, m: float, b: float, nu: float = 0.0) -> None:
        self._rate = 1.0 / tau
        self._m = m
        self._beta = b / m
        self.nu = nu

    def coefficients(self, h: float) -> tuple[float, ...]:
        """``(e^{-lambda h}, lambda h exp[-lambda h, -beta h], lambda h^2 exp[-lambda h, -beta h, 0] / m)``."""
        rh, ch = self._rate * h, self._beta * h
        return (math.exp(-rh), rh * exp_divided_difference(-rh, -ch), rh * h / self._m * exp_divided_difference(-rh, -ch, 0.0))

    def restart(self) -> None:
        """A filter has no window."""

    def track(self, coefficients: tuple[float, ...], v0: float, net: float, dx: float) -> None:
        """Advance ``nu`` over the stretch (``v0`` m/s, ``net`` N held)."""
        decay, from_velocity, from_force = coefficients
        self.nu = decay * self.nu + from_velocity * v0 + from_force * net

    def value(self) -> float:
        """The filtered velocity, m/s."""
        return self.nu


VelocityMeter = WindowMeter | LowpassMeter


def make_meter(parameters: DeviceParameters, previous: Meter | None, velocity: float) -> VelocityMeter | None:
    """The measurement state of ``parameters.velocity`` (None for ``point``: the handle's velocity itself).

    A filter keeps the ``previous`` filter's state, or starts settled at the handle's ``velocity``.
    """
    model = parameters.velocity
    window = model.window(parameters.period)
    if window is not None:
        return WindowMeter(window, parameters.period)
    if model.kind == "lowpass":
        nu = previous.nu if isinstance(previous, LowpassMeter) else velocity
        return LowpassMeter(model.time, parameters.mass, parameters.friction, nu)
    return None


class Sensor:
    """The drive's encoder and velocity estimate, sampled at each SYNC.

    ``meter`` is the velocity model's state the handle carries (None for ``point``).
    """

    def __init__(self, parameters: DeviceParameters) -> None:
        self.velocity_counts = 0
        self.position_counts = 0
        self.meter: VelocityMeter | None = None
        self._seed: int | None = None
        self._random: random.Random | None = None
        self.configure(parameters)

    def configure(self, parameters: DeviceParameters, velocity: float = 0.0) -> None:
        """Take new scaling (counts per m/s and per m), velocity model and noise; ``velocity`` (m/s) is the
        handle's, where a new filter starts.  The noise generator is reseeded only when ``noise_seed`` changes."""
        self._per_velocity = 1.0 / parameters.velocity_per_count
        self._per_position = 1.0 / parameters.position_per_count
        self.meter = make_meter(parameters, self.meter, velocity)
        self._noise = parameters.velocity_noise
        if self._random is None or parameters.noise_seed != self._seed:
            self._seed = parameters.noise_seed
            self._random = random.Random(self._seed)
        self._gauss = self._random.gauss

    def sample(self, handle: Handle | TwoMassHandle) -> None:
        """Quantise the velocity estimate (plus noise) and the encoder's position now (a transmission's motor side)."""
        meter = self.meter
        counts = (handle.velocity if meter is None else meter.value()) * self._per_velocity
        if self._noise:
            counts += self._gauss(0.0, self._noise)
        velocity = round(counts)
        position = round(handle.position * self._per_position)
        self.velocity_counts = velocity if _LOW <= velocity <= _HIGH else saturate(velocity, _LOW, _HIGH)
        self.position_counts = position if _LOW <= position <= _HIGH else saturate(position, _LOW, _HIGH)
