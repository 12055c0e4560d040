"""The linear, in-contact model of the haptic loop that the passivity analysis judges.

A handle (mass ``m`` kg, viscous friction ``b`` N s/m) sampled every ``T`` s, a virtual
wall (stiffness ``K`` N/m, damping ``B`` N s/m) discretised by ``discretisation``, and a loop
delay of ``delay`` whole samples between the velocity sample and the force it produces
(0: the seed's ideal loop, 1: a CiA-402 synchronous cycle).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from haptic_bus.validation import real_in_range, whole_in_range

# Physically meaningful bounds, wide enough for any real device, narrow enough that every
# derived quantity (b T / m, K T^2 / m, ...) stays finite in double precision.
MASS_RANGE = (1e-9, 1e9)  # kg
FRICTION_RANGE = (0.0, 1e12)  # N s/m
PERIOD_RANGE = (1e-9, 10.0)  # s
STIFFNESS_RANGE = (0.0, 1e15)  # N/m
DAMPING_RANGE = (0.0, 1e15)  # N s/m
DELAY_RANGE = (0, 64)  # samples

BANDWIDTH_ALPHA = 6.0
"""Eq. (25): ``alpha = B/(KT)`` must exceed this (crossover below 0.1 Nyquist, corner at half of it)."""


class Discretisation(enum.Enum):
    """How the continuous wall ``K/s + B`` becomes ``K_d(z)``."""

    BACKWARD_DIFFERENCE = "backward"


class Sampling(enum.Enum):
    """Which signal the controller samples (the seed's section II vs III)."""

    VELOCITY = "velocity"
    POSITION = "position"


@dataclass(frozen=True)
class WallLoop:
    """Validated parameters of one linear wall loop (SI units, delay in samples)."""

    m: float
    b: float
    T: float
    K: float
    B: float
    delay: int = 0
    discretisation: Discretisation = Discretisation.BACKWARD_DIFFERENCE

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "m", real_in_range("m", self.m, *MASS_RANGE, unit="kg"))
        set_(self, "b", real_in_range("b", self.b, *FRICTION_RANGE, unit="N s/m"))
        set_(self, "T", real_in_range("T", self.T, *PERIOD_RANGE, unit="s"))
        set_(self, "K", real_in_range("K", self.K, *STIFFNESS_RANGE, unit="N/m"))
        set_(self, "B", real_in_range("B", self.B, *DAMPING_RANGE, unit="N s/m"))
        set_(self, "delay", whole_in_range("delay", self.delay, *DELAY_RANGE))
        if not isinstance(self.discretisation, Discretisation):
            set_(self, "discretisation", Discretisation(self.discretisation))

    @property
    def c(self) -> float:
        """``b T / m``: the plant's decay over one sample (dimensionless)."""
        return self.b * self.T / self.m

    @property
    def alpha(self) -> float:
        """The seed's ``alpha = B / (K T)`` (inf when K = 0)."""
        return self.B / (self.K * self.T) if self.K > 0 else float("inf")

    @property
    def beta(self) -> float:
        """The seed's ``beta = b / B`` (inf when B = 0)."""
        return self.b / self.B if self.B > 0 else float("inf")

    def with_wall(self, K: float, B: float) -> "WallLoop":
        """The same device and loop with another wall."""
        return WallLoop(self.m, self.b, self.T, K, B, self.delay, self.discretisation)
