"""The linear, in-contact model of the haptic loop that the passivity analysis judges.

A handle (mass ``m`` kg, viscous friction ``b`` N s/m) sampled every ``T`` s, a virtual
wall (stiffness ``K`` N/m, damping ``B`` N s/m) discretised by ``discretisation``, the
velocity the drive reports (``velocity``, :mod:`haptic_bus.analysis.velocity`), and a loop
delay of ``delay = D = d + delta`` samples (real, ``d`` whole, ``0 <= delta < 1``) between
the velocity sample at ``kT`` and the moment ``(k + D) T`` the force it produces is applied
(0: the seed's ideal loop, 1: a CiA-402 synchronous cycle, 0.3: a drive that applies the RPDO
on reception after 0.3 T of bus and compute time).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from haptic_bus.analysis.resolution import Quantisation
from haptic_bus.analysis.velocity import POINT, VelocityModel
from haptic_bus.validation import real_in_range

if TYPE_CHECKING:
    from haptic_bus.analysis.transmission import Transmission

# Physically meaningful bounds, wide enough for any real device, narrow enough that every
# derived quantity (b T / m, K T^2 / m, ...) stays finite in double precision.
MASS_RANGE = (1e-9, 1e9)  # kg
FRICTION_RANGE = (0.0, 1e12)  # N s/m
PERIOD_RANGE = (1e-9, 10.0)  # s
STIFFNESS_RANGE = (0.0, 1e15)  # N/m
DAMPING_RANGE = (0.0, 1e15)  # N s/m
DELAY_RANGE = (0, 1000)  # samples (real)
WORDS = {"m": "mass", "b": "friction", "T": "period", "K": "stiffness", "B": "damping"}
"""The paper's symbols (the loop objects' fields) -> the words users type (the package docstring's vocabulary)."""

BANDWIDTH_ALPHA = 6.0
"""Eq. (25): ``alpha = B/(KT)`` must exceed this (crossover below 0.1 Nyquist, corner at half of it)."""


class Discretisation(enum.Enum):
    """How the continuous wall ``K/s + B`` becomes ``K_d(z)``."""

    BACKWARD_DIFFERENCE = "backward"


@dataclass(frozen=True)
class WallLoop:
    """Validated parameters of one linear wall loop (SI units, delay in samples).

    ``delay`` is kept an ``int`` when it is whole (``1``, not ``1.0``); ``velocity`` accepts a
    :class:`VelocityModel` or its profile string (``"average"``, ``"lowpass:0.002"``, ...).
    """

    m: float
    b: float
    T: float
    K: float
    B: float
    delay: float = 0
    velocity: VelocityModel = POINT
    discretisation: Discretisation = Discretisation.BACKWARD_DIFFERENCE

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "m", real_in_range("m", self.m, *MASS_RANGE, unit="kg"))
        set_(self, "b", real_in_range("b", self.b, *FRICTION_RANGE, unit="N s/m"))
        set_(self, "T", real_in_range("T", self.T, *PERIOD_RANGE, unit="s"))
        set_(self, "K", real_in_range("K", self.K, *STIFFNESS_RANGE, unit="N/m"))
        set_(self, "B", real_in_range("B", self.B, *DAMPING_RANGE, unit="N s/m"))
        delay = real_in_range("delay", self.delay, *DELAY_RANGE, unit="samples")
        set_(self, "delay", int(delay) if delay.is_integer() else delay)
        velocity = VelocityModel.parse(self.velocity)
        velocity.check_period(self.T)
        set_(self, "velocity", velocity)
        if not isinstance(self.discretisation, Discretisation):
            set_(self, "discretisation", Discretisation(self.discretisation))

    @property
    def c(self) -> float:
        """``b T / m``: the plant's decay over one sample (dimensionless)."""
        return self.b * self.T / self.m

    @property
    def kappa(self) -> float:
        """``K T^2 / m``: the wall's stiffness in the loop's own units (dimensionless)."""
        return self.K * self.T * self.T / self.m

    @property
    def q(self) -> float:
        """``B T / m``: the wall's damping in the loop's own units (dimensionless)."""
        return self.B * self.T / self.m

    @property
    def whole_delay(self) -> int:
        """``d``: the whole samples of the delay ``D = d + delta``."""
        return math.floor(self.delay)

    @property
    def fractional_delay(self) -> float:
        """``delta`` in [0, 1): the fraction of a sample of the delay ``D = d + delta``."""
        return float(self.delay - math.floor(self.delay))

    @property
    def lossless(self) -> bool:
        """A free frictionless mass (``b = K = B = 0``): no dissipation and no wall at all."""
        return self.b == 0.0 and self.K == 0.0 and self.B == 0.0

    @property
    def oscillator(self) -> bool:
        """A spring alone on a frictionless handle, no delay, point velocity (``b = B = 0 < K``,
        ``K T^2/m < 4``): a lossless oscillator, its poles on the unit circle."""
        return (self.b == 0.0 and self.B == 0.0 and self.K > 0.0 and self.delay == 0
                and self.velocity.kind == "point" and self.kappa < 4.0)

    @property
    def alpha(self) -> float:
        """The seed's ``alpha = B / (K T)`` (inf when K = 0)."""
        return self.B / (self.K * self.T) if self.K > 0 else float("inf")

    @property
    def beta(self) -> float:
        """The seed's ``beta = b / B`` (inf when B = 0)."""
        return self.b / self.B if self.B > 0 else float("inf")

    def with_wall(self, K: float, B: float) -> WallLoop:
        """The same device, velocity model and delay with another wall."""
        return WallLoop(self.m, self.b, self.T, K, B, self.delay, self.velocity, self.discretisation)

    def with_delay(self, delay: float) -> WallLoop:
        """The same device, velocity model and wall with another delay (samples)."""
        return WallLoop(self.m, self.b, self.T, self.K, self.B, delay, self.velocity, self.discretisation)


@dataclass(frozen=True)
class DeviceLoop:
    """The loop the walls run in, without a wall: ``m`` kg, effective ``b`` N s/m, ``T`` s,
    ``delay`` samples (real), and the ``velocity`` model of the drive's 0x606C (a model or its
    profile string).  What the gate holds (:class:`~haptic_bus.control.gate.PassivityGate`);
    :meth:`wall` adds a wall and gives the :class:`WallLoop` the criterion judges.  With a
    ``quantisation`` (encoder resolution and Coulomb friction) the gate judges every wall's
    quantisation condition too (:mod:`haptic_bus.analysis.quantisation`).  A ``transmission``
    (:class:`~haptic_bus.analysis.transmission.Transmission`, None: a rigid handle) makes ``m``,
    ``b`` the handle's and the gate judge the two-mass loop
    (:mod:`haptic_bus.analysis.two_mass_criterion`)."""

    m: float
    b: float
    T: float
    delay: float
    velocity: VelocityModel | str = POINT
    quantisation: Quantisation | None = None
    transmission: Transmission | None = None

    def __post_init__(self) -> None:
        self.wall(0.0, 0.0)  # validated as a loop is (ParameterError naming m, b, T, delay or velocity): usable once it exists

    def wall(self, K: float, B: float) -> WallLoop:
        """The linear loop with the wall ``K`` N/m, ``B`` N s/m (validated)."""
        return WallLoop(self.m, self.b, self.T, K, B, self.delay, VelocityModel.parse(self.velocity))

    def describe(self) -> str:
        """``m = .. kg, b = .. N s/m, T = .. s, delay D = .. samples, velocity ..`` for messages."""
        return (f"m = {self.m:g} kg, b = {self.b:g} N s/m, T = {self.T:g} s, delay D = {self.delay:g} samples, "
                f"velocity {VelocityModel.parse(self.velocity)}"
                + ("" if self.transmission is None else f", transmission {self.transmission.describe()}"))
