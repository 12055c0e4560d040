"""The wall loop with a quantised encoder and Coulomb friction, simulated exactly (the arbiter of
:mod:`haptic_bus.analysis.quantisation`).

The handle: ``m dv/dt = w - u - b v - f_c sgn(v)``, sticking (``v = 0``) while
``|w - u| <= f_c``.  The operator's force is ``w = p(t) - c v``: a push ``p`` held constant over
each of the ``substeps`` steps of a period (any piecewise-constant force; a sum of tones enters
as its value at each step's middle) and a hand damping ``c >= 0`` N s/m through which the
operator takes energy out of any motion the loop keeps up.

**Exact between events.**  Over a stretch where ``p`` and the wall force ``u`` are constant and
the handle slides one way (``s = sgn v``), ``v`` obeys a linear ODE with the constant
acceleration ``g = (p - u - s f_c)/m`` and the decay ``a = (b + c)/m``:
``v(t) = v0 e^{-at} + g t phi1(at)``, ``x(t) = x0 + v0 t phi1(at) + g t^2 phi2(at)``
(:mod:`haptic_bus.analysis.plant`).  ``v`` is monotone there, so it reaches 0 at most once, at
a time in closed form (``log1p``); then the handle sticks for the rest of the stretch if
``|p - u| <= f_c``, else it slides off the other way (and cannot turn again: the force is
constant).  No sub-stepping error: the run is exact to round-off for its input.

**The measurement** at each SYNC ``kT`` (:class:`Quantiser`): the encoder count
``n = floor(x/Delta)`` (or ``round``) of the true position, so the drive's positions are
``Delta n``; ``average``: ``y_k = (n_k - n_{k-1}) Delta / T`` (0x606C as the count difference,
exact when ``Delta / (T vq)`` is whole); ``window:TW``: ``(n_k - n(kT - TW)) Delta / TW``;
``point``: ``v(kT)`` rounded to the velocity quantum ``vq``.  (``lowpass`` is not simulated
here: its wall position integrates a rounded velocity like ``point``'s.)  The controller:
``x_k = x_{k-1} + T y_k`` from ``x_{-1} = 0``, ``u_k = K x_k + B y_k``, held by the drive
from ``(k + D) T`` (``u_{k-d-1}`` over the first ``delta T`` of period ``k``, then ``u_{k-d}``).

**The operator's energy** ``E(t) = int_0^t w v dt = sum p dx - c int v^2 dt`` (J) is summed
exactly per stretch; its least value inside a stretch is found too (``dE/dt = v (p - c v)``
changes sign inside a stretch only where ``v = p/c``, solved in closed form), so
:attr:`QuantisedRun.least_energy` is the least ``E`` over the whole run, not only at samples.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import phi1, phi2, stop_time
from haptic_bus.analysis.resolution import COULOMB_RANGE, RESOLUTION_RANGE, VELOCITY_RESOLUTION_RANGE
from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range, whole_in_range

ROUNDINGS = ("floor", "round")
MAX_STEPS = 5_000_000


@dataclass(frozen=True)
class Quantiser:
    """The drive's resolution: ``position`` Delta m per 0x6064 increment (0: exact), the
    ``velocity`` quantum vq m/s of a ``point`` 0x606C (0: exact), and how counts are formed
    (``"floor"``: an incremental encoder's count, ``"round"``)."""

    position: float
    velocity: float = 0.0
    rounding: str = "floor"

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", real_in_range("position_resolution", self.position, *RESOLUTION_RANGE, unit="m"))
        object.__setattr__(self, "velocity", real_in_range("velocity_resolution", self.velocity, *VELOCITY_RESOLUTION_RANGE,
                                                                 unit="m/s"))
        if self.rounding not in ROUNDINGS:
            raise ParameterError("rounding", self.rounding, " or ".join(ROUNDINGS))

    def count(self, x: float) -> float:
        """The drive's position of the true ``x`` (m): ``Delta floor(x/Delta)`` or ``Delta round(x/Delta)``."""
        if self.position == 0.0:
            return x
        step = math.floor(x / self.position + (0.5 if self.rounding == "round" else 0.0))
        return step * self.position

    def speed(self, v: float) -> float:
        """A ``point`` 0x606C of the true ``v`` (m/s): rounded to the velocity quantum."""
        return v if self.velocity == 0.0 else round(v / self.velocity) * self.velocity


@dataclass(frozen=True)
class Hand:
    """The operator: ``pushes`` (N), one per step of ``T/substeps``, and a ``damping`` c (N s/m)."""

    pushes: tuple[float, ...]
    substeps: int = 1
    damping: float = 0.0

    def __post_init__(self) -> None:
        whole_in_range("substeps", self.substeps, 1, 64)
        if not self.pushes or len(self.pushes) % self.substeps or len(self.pushes) > MAX_STEPS:
            raise ParameterError("pushes", len(self.pushes), f"a positive multiple of substeps = {self.substeps}, "
                                                             f"at most {MAX_STEPS}")
        for push in self.pushes:
            if not math.isfinite(push):
                raise ParameterError("push", push, "a finite force in N")
        real_in_range("damping", self.damping, 0.0, 1e12, unit="N s/m")

    @property
    def samples(self) -> int:
        """Controller periods the hand acts for."""
        return len(self.pushes) // self.substeps


@dataclass(frozen=True)
class QuantisedRun:
    """A run from rest: per sample ``k`` the true ``position`` x(kT) (m), ``velocity`` (m/s),
    the controller's ``wall_position`` x_k (m) and ``wall_force`` u_k (N), and the operator's
    ``energy`` E(kT) (J); ``least_energy`` the least E over the whole run (J) and ``work_scale``
    the sum of ``|p dx|`` and ``c int v^2`` (J), the scale of the round-off in E, summed over ``terms`` stretches."""

    position: np.ndarray
    velocity: np.ndarray
    wall_position: np.ndarray
    wall_force: np.ndarray
    energy: np.ndarray
    least_energy: float
    work_scale: float
    terms: int

    def roundoff_bound(self) -> float:
        """A bound (J) on the round-off in any E: ``64 n u sum|work|`` (recursive summation of
        ``n`` terms errs by at most ``(n - 1) u sum|x_i|``, Higham eq. 4.4; each term carries a
        few ulps of its own, and the factor 64 covers them)."""
        return 64.0 * self.terms * 2.0**-53 * self.work_scale


class _Handle:
    """The handle's exact motion under a constant push and wall force, with Coulomb friction, from
    rest at ``start`` (m)."""

    def __init__(self, m: float, b: float, coulomb: float, damping: float, start: float) -> None:
        self.m, self.coulomb, self.damping = m, coulomb, damping
        self.a = (b + damping) / m
        self.x = start
        self.v = 0.0
        self.energy = 0.0
        self.least = 0.0
        self.scale = 0.0
        self.terms = 0

    def advance(self, h: float, push: float, wall: float) -> None:
        """Move over ``h`` s with the push ``p`` and the wall force ``u`` (N) held."""
        net = push - wall
        while h > 0.0:
            if self.v == 0.0:
                if abs(net) <= self.coulomb:
                    return  # sticks for the rest: no motion, no work
                direction = math.copysign(1.0, net)
            else:
                direction = math.copysign(1.0, self.v)
            g = (net - direction * self.coulomb) / self.m
            stop = self._stop_time(g, direction)
            used = h if stop is None or stop >= h else stop
            self._slide(used, g, push, stopped=used == stop)
            h -= used

    def _stop_time(self, g: float, direction: float) -> float | None:
        """When the sliding handle reaches ``v = 0`` (s), None if it never does."""
        if self.v == 0.0 or g * direction >= 0.0:
            return None  # accelerating away from 0, or coasting towards it only asymptotically (g = 0, a > 0)
        return stop_time(1.0, self.a, direction * self.v, -direction * g)  # per unit mass: decay a 1/s, braking |g| m/s^2

    def _slide(self, t: float, g: float, push: float, stopped: bool) -> None:
        v0, a, c = self.v, self.a, self.damping
        at = a * t
        dx = v0 * t * phi1(at) + g * t * t * phi2(at)
        v1 = 0.0 if stopped else v0 * math.exp(-at) + g * t * phi1(at)
        dissipated = c * self._square_integral(v0, g, t) if c > 0.0 else 0.0
        if c > 0.0 and push != 0.0:  # dE/dt = v (p - c v) turns sign where v = p/c
            turn = self._time_of_velocity(v0, g, push / c, t)
            if turn is not None:
                at_turn = a * turn
                x_turn = v0 * turn * phi1(at_turn) + g * turn * turn * phi2(at_turn)
                self.least = min(self.least, self.energy + push * x_turn - c * self._square_integral(v0, g, turn))
        self.x += dx
        self.v = v1
        self.energy += push * dx - dissipated
        self.scale += abs(push * dx) + dissipated
        self.terms += 1
        self.least = min(self.least, self.energy)

    def _time_of_velocity(self, v0: float, g: float, target: float, t: float) -> float | None:
        """The time in (0, t) at which ``v = target`` (needs ``a > 0``), None if none."""
        a = self.a
        limit = g / a
        if (v0 - limit) == 0.0 or (target - limit) / (v0 - limit) <= 0.0:
            return None
        when = -math.log((target - limit) / (v0 - limit)) / a
        return when if 0.0 < when < t else None

    def _square_integral(self, v0: float, g: float, t: float) -> float:
        """``int_0^t v^2`` (m^2/s) with ``v = L + (v0 - L) e^{-a tau}``, ``L = g/a`` (``a > 0``)."""
        a = self.a
        limit, excess = g / a, v0 - g / a
        one = t * phi1(a * t)
        two = t * phi1(2.0 * a * t)
        return limit * limit * t + 2.0 * limit * excess * one + excess * excess * two


def simulate_quantised(loop: WallLoop, hand: Hand, quantiser: Quantiser, coulomb: float = 0.0,
                       start: float = 0.0) -> QuantisedRun:
    """Run ``loop`` from rest at the true position ``start`` (m) with the drive's ``quantiser``,
    Coulomb friction ``coulomb`` (N) and the operator ``hand``; exact (see the module docstring)."""
    coulomb = real_in_range("coulomb", coulomb, *COULOMB_RANGE, unit="N")
    start = real_in_range("start", start, -1e6, 1e6, unit="m")
    kind = loop.velocity.kind
    if kind == "lowpass":
        raise ParameterError("velocity", str(loop.velocity), "point, average or window (lowpass is not simulated)")
    T, K, B = loop.T, loop.K, loop.B
    d, delta = loop.whole_delay, loop.fractional_delay
    width = loop.velocity.window(T)
    reset = None if width is None else 1.0 - min(width, T) / T
    steps = hand.substeps
    bounds = sorted({j / steps for j in range(steps)} | {delta} | ({reset} if reset is not None else set()) | {1.0})
    handle = _Handle(loop.m, loop.b, coulomb, hand.damping, start)
    n = hand.samples
    forces = [0.0] * (d + 2)  # u_{k-d-1} .. u_k, oldest first
    last = quantiser.count(start)
    window_start = last
    wall = 0.0
    out = np.empty((5, n))
    pushes = hand.pushes
    for k in range(n):
        counted = quantiser.count(handle.x)
        if kind == "point":
            y = quantiser.speed(handle.v)
        elif kind == "average":
            y = (counted - last) / T
        else:
            y = (counted - window_start) / (width or T)
        last = counted
        wall += T * y
        forces = [*forces[1:], K * wall + B * y]
        out[:, k] = handle.x, handle.v, wall, forces[-1], handle.energy
        before, now = forces[0], forces[1]
        for lo, hi in itertools.pairwise(bounds):
            if reset is not None and lo == reset:
                window_start = quantiser.count(handle.x)
            push = pushes[k * steps + min(int(lo * steps + 1e-9), steps - 1)]
            handle.advance((hi - lo) * T, push, before if hi <= delta else now)
    return QuantisedRun(out[0], out[1], out[2], out[3], out[4], handle.least, handle.scale, handle.terms)
