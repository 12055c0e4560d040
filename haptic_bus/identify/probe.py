"""Is the handle free to move?  The probe that runs before any excitation.

In each direction (+x, then -x) the probe pushes with a force that doubles from 1/32 of the
force limit up to the limit, until the handle has moved ``target`` m.  At force ``F`` the push
lasts at most ``t_max`` (:func:`free_travel_time`, no longer than :data:`MAX_PUSH_SECONDS`): the
time the slowest handle that still counts as free needs to cover ``target`` -- one
:data:`MASS_FACTOR` times heavier than the profile's ``m``, with a viscous time constant ``m/b``
of :data:`MIN_TIME_CONSTANT` (so ``b = MASS_FACTOR m / MIN_TIME_CONSTANT``) and Coulomb friction
taking :data:`COULOMB_SHARE` of the push.  (Viscous friction matters: a handle with a drive's
damping, ``m/b`` = 50 ms, needs several times longer than a frictionless one, and was refused
as blocked before it counted.)  Once the target is reached the same force brakes the handle
until it stops moving forward, then the force is removed for :data:`REST_SECONDS`.

The handle is **free** when, in both directions, some force up to the limit moved it ``target``
within ``t_max`` (so it moves like a free handle of at most ``MASS_FACTOR m``, ``m/b`` at least
``MIN_TIME_CONSTANT``, Coulomb friction at most ``COULOMB_SHARE`` of the force: not blocked, not
against an end stop, not held by friction near or above the force limit), and it stayed where the
brake left it (a handle held by a spring -- a hand, a compliant stop -- springs back more than
:data:`SPRING_BACK` of its excursion).  Otherwise the identification is refused before any
excitation.  Units: s, m, N.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from dataclasses import dataclass

from scipy.special import lambertw

LEVELS = 6  # forces F_limit / 2^5 .. F_limit
MASS_FACTOR = 4.0  # a free handle is at most this much heavier than the profile says
MIN_TIME_CONSTANT = 0.01  # s: m/b of a free handle at least (published desktop plants 9-50 ms, a damped servo axis 50 ms)
COULOMB_SHARE = 0.5  # of the push: the Coulomb friction a free handle may have at most
MIN_PUSH_SAMPLES = 5
MAX_PUSH_SECONDS = 0.5
REST_SECONDS = 0.1
SPRING_BACK = 0.5  # of the excursion: a free handle keeps more than half of it

Phase = Generator[float, float, "tuple[ProbeResult, float]"]
"""A phase of the run: sent each cycle's position (m), yields that cycle's force (N); returns
its result and the position it was last sent (to which the next phase answers)."""


def free_travel_time(distance: float, mass: float, force: float, time_constant: float) -> float:
    """The time (s) a handle of ``mass`` kg with viscous time constant ``time_constant`` s (``b = mass /
    time_constant``) needs to move ``distance`` m from rest under a constant net ``force`` N.

    ``x(t) = (F tau / m) (t - tau (1 - exp(-t/tau)))``; with ``s = t/tau`` and ``c = x m / (F tau^2)``,
    ``s - 1 + exp(-s) = c`` has the root ``s = c + 1 + W0(-exp(-(c + 1)))`` (Lambert's W, principal
    branch).  For ``c`` below 1e-6 (a nearly frictionless push, where the closed form cancels) the
    frictionless ``s = sqrt(2 c)`` is used, within 1e-4 of the root there.
    """
    c = distance * mass / (force * time_constant * time_constant)
    if c < 1e-6:
        return time_constant * math.sqrt(2.0 * c)
    return time_constant * (c + 1.0 + float(lambertw(-math.exp(-(c + 1.0))).real))


@dataclass(frozen=True)
class ProbeSettings:
    """The probe's numbers: ``period`` s, ``force_limit`` N, ``target`` m to move, ``mass`` kg (the profile's)."""

    period: float
    force_limit: float
    target: float
    mass: float

    def push_samples(self, force: float) -> int:
        """The longest push at ``force`` N, in cycles (see the module docstring)."""
        seconds = free_travel_time(self.target, MASS_FACTOR * self.mass, (1.0 - COULOMB_SHARE) * force, MIN_TIME_CONSTANT)
        return max(MIN_PUSH_SAMPLES, math.ceil(min(MAX_PUSH_SECONDS, seconds) / self.period))

    def levels(self) -> list[float]:
        """The probe forces in N, weakest first."""
        return [self.force_limit * 2.0 ** (level - LEVELS + 1) for level in range(LEVELS)]


@dataclass(frozen=True)
class ProbeResult:
    """The verdict: ``free``, a one-line ``message``, the ``force`` (N) that moved the handle (the
    larger of the two directions), the largest excursion (m) in each direction (+, -), and the
    ``apparent_mass`` (kg) of the lighter-looking push (:func:`doublet_mass`)."""

    free: bool
    message: str
    force: float
    excursions: tuple[float, float]
    apparent_mass: float = math.nan


@dataclass(frozen=True)
class _Push:
    reached: bool
    excursion: float  # m, in the push direction, the largest
    kept: float  # m, in the push direction, after the rest
    seconds: float  # how long the push lasted
    mass: float  # kg, doublet_mass of the push and brake (inf if the target was not reached)


def _push(x: float, direction: float, force: float, settings: ProbeSettings) -> Generator[float, float, tuple[_Push, float]]:
    """Push ``direction`` (+-1) with ``force`` N until ``target`` or the push limit, brake, rest."""
    origin, peak, previous = x, 0.0, x
    limit = settings.push_samples(force)
    pushed = 0
    while direction * (x - origin) < settings.target and pushed < limit:
        previous = x
        x = yield direction * force
        pushed += 1
        peak = max(peak, direction * (x - origin))
    reached = direction * (x - origin) >= settings.target
    speed, covered = direction * (x - previous) / settings.period, direction * (x - origin)
    for _ in range(limit):  # brake while it still moves forward
        previous = x
        x = yield -direction * force
        peak = max(peak, direction * (x - origin))
        if direction * (x - previous) <= 0.0:
            break
    for _ in range(math.ceil(REST_SECONDS / settings.period)):
        x = yield 0.0
        peak = max(peak, direction * (x - origin))
    mass = doublet_mass(force, speed, covered, peak) if reached else math.inf
    return _Push(reached, peak, direction * (x - origin), pushed * settings.period, mass), x


def doublet_mass(force: float, speed: float, pushed: float, peak: float) -> float:
    """The mass (kg) a push-and-brake doublet shows: ``2 F / (a_push + a_brake)``.

    Pushed with ``F`` N over ``pushed`` m to ``speed`` m/s from rest, braked with ``-F`` to a stop
    at ``peak`` m: ``a_push = v^2/(2 pushed)`` is ``(F - Fc - b v)/m`` on average and
    ``a_brake = v^2/(2 (peak - pushed))`` is ``(F + Fc + b v)/m``, so friction cancels in the sum
    (Coulomb exactly, viscous to first order).  The loop delay lets the push act a little into
    the brake, which makes the mass look slightly larger.
    """
    push = speed * speed / (2.0 * pushed)
    brake = speed * speed / (2.0 * max(peak - pushed, 1e-12))
    return 2.0 * force / (push + brake)


def probe(x: float, settings: ProbeSettings) -> Phase:
    """The probe as a phase, starting from position ``x`` m (see the module docstring)."""
    moved: list[_Push] = []
    forces: list[float] = []
    for direction, name in ((1.0, "+x"), (-1.0, "-x")):
        attempt = None
        for force in settings.levels():
            attempt, x = yield from _push(x, direction, force, settings)
            if attempt.reached:
                forces.append(force)
                break
        assert attempt is not None
        if not attempt.reached:
            message = (f"the handle is not free to move towards {name}: {attempt.excursion * 1e3:.3g} mm under "
                       f"{settings.force_limit:.3g} N (the force limit) for {attempt.seconds * 1e3:.3g} ms, where a free handle "
                       f"of up to {MASS_FACTOR:g} x {settings.mass:g} kg moves {settings.target * 1e3:.3g} mm: blocked, "
                       "at an end stop, or held by friction above the force limit")
            return ProbeResult(False, message, settings.force_limit, _excursions(moved, attempt)), x
        if attempt.kept < SPRING_BACK * attempt.excursion:
            moved_mm, kept_mm = attempt.excursion * 1e3, attempt.kept * 1e3
            kept = (f"it kept {kept_mm:.3g} mm of its {moved_mm:.3g} mm" if kept_mm >= 0 else
                    f"it came back past its start, {-kept_mm:.3g} mm beyond it, after {moved_mm:.3g} mm")
            message = (f"the handle springs back after a push towards {name}: {kept}; something holds it or pushes it "
                       "(a hand, a compliant stop)")
            return ProbeResult(False, message, forces[-1], _excursions(moved, attempt)), x
        moved.append(attempt)
    message = (f"free: it moved {moved[0].excursion * 1e3:.3g} mm towards +x under {forces[0]:.3g} N and "
               f"{moved[1].excursion * 1e3:.3g} mm towards -x under {forces[1]:.3g} N")
    return ProbeResult(True, message, max(forces), _excursions(moved), min(push.mass for push in moved)), x


def _excursions(moved: list[_Push], last: _Push | None = None) -> tuple[float, float]:
    done = [*moved, last] if last is not None else moved
    first, second = (done + [_Push(False, 0.0, 0.0, 0.0, math.inf)] * 2)[:2]
    return first.excursion, second.excursion
