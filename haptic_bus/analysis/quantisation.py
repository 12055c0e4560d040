"""Encoder quantisation and Coulomb friction: the passivity condition the linear criterion leaves out.

The drive counts the handle's position in increments of ``Delta`` m (``position_per_count``)
and reports 0x606C in quanta of ``vq`` m/s (``velocity_per_count``).  The controller's wall
then acts on the measured, not the true, motion: ``u_k = K x_k + B y_k`` with
``x_k = x_{k-1} + T y_k``.  Write the measurement as the linear loop's plus an error,
``y_k = y_k^lin + e^y_k`` and ``x_k = x_k^lin + e^x_k``.  The operator can move the handle
along any path (he is a force source), so his energy from rest is

    E = E_lin + f_c L + sum_k (K e^x_k + B e^y_k) dx'_k,

``E_lin`` the linear loop's energy on the same path (``>= 0`` where the exact criterion passes),
``L`` the path length, ``f_c`` the Coulomb friction (N) and ``dx'_k`` the handle's travel while
the force computed at sample ``k`` is held -- over any delay ``D = d + delta``, each instant
has one held force, so the ``dx'_k`` add up to the path once.  Whether the error term can beat
``f_c L`` depends on which quantum enters ``x_k``:

* ``average`` (0x606C the count difference over the cycle, exact when ``Delta/(T vq)`` is
  whole, as in every shipped profile; otherwise its rounding drifts as ``point``'s does):
  ``x_k = Delta n_k`` is the quantised encoder position
  itself, ``e^x`` stays in one count and ``e^y = (e^x_k - e^x_{k-1})/T``.  A constant part of
  ``e^x`` is a spring shifted by at most ``Delta/2`` (conservative: a bounded one-off); the rest is
  within ``Delta/2``, and ``|e^y| < Delta/T``.  So the loop is passive if

      f_c >= K Delta/2 + B Delta/T            (any delay; Abbott & Okamura's f_c > K Delta/2 at B = 0)

  **per crossing**: near an encoder level the held force lags the count by ``D`` samples plus
  the hold, so the operator can cross the level and turn back while the force still says the
  other side; each metre of that chatter returns up to ``K Delta/2 + B Delta/T`` joules, and
  Coulomb friction takes ``f_c``.  At ``B = 0`` the condition is also necessary at every delay:
  a push that parks the handle between two levels (net force ``+- K Delta/2``) can never stick
  when ``f_c < K Delta/2``, the relay keeps a limit cycle up, and a hand with any damping takes
  energy out of it for ever.  With ``B > 0`` the damper's share ``B Delta/T`` is proven
  sufficient and nearly needed: on the issue's wall with ``B = 2`` N s/m (bound 0.1375 N) the
  exact simulation finds a dithered park active at 0.13 N, at ``D = 0`` and ``D = 1``, and
  nothing at or above the bound (the manual page ``docs/quantisation.md`` has the numbers).
  The leak stated is per count of travel: ``(K Delta/2 + B Delta/T - f_c) Delta`` J.
* ``point`` and ``lowpass`` (0x606C a rounded instantaneous or filtered velocity): ``x_k`` is
  ``T`` times a sum of rounded velocities; the rounding never cancels out, and a creep slower
  than ``vq/2`` is not seen at all.  A **drift**: push in fast by ``A``, creep out unseen, and the
  wall still pushes with its full force ``K A`` all the way out: each such cycle returns
  ``K A^2/2`` and costs ``2 f_c A``, so every ``A > 4 f_c/K`` leaks.  It repeats with the
  wall's position back where it was: creep in by ``A`` unseen, push in by ``A`` seen, creep out
  by ``A`` unseen, pull out by ``A`` seen -- ``K A^2`` returned, ``4 f_c A`` of friction per
  cycle.  No Coulomb friction makes a spring passive here; a force limit ``F`` only bounds
  ``A`` by ``F/K``, so the cycle leaks wherever ``F > 4 f_c``.  A damper alone (``K = 0``)
  errs by ``B vq/2`` per unit travel: ``f_c >= B vq/2``.
* ``window:TW``: ``x_k`` sums count differences over windows shorter than the cycle; a count
  that changes outside the window is never seen: the same drift with ``Delta`` (``K > 0``), and
  ``f_c >= B Delta/TW`` for a damper alone.

Without a quantum (``Delta = 0`` for average and window, ``vq = 0`` for point and lowpass)
the condition holds trivially.  :func:`quantisation_condition` judges one wall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.resolution import Quantisation

_FORMULAS = {"average": ("K Delta/2 + B Delta/T", "Delta = {:g} m"), "window": ("B Delta/TW", "Delta = {:g} m")}
CROSSING = "crossing"
DRIFT = "drift"
EXACT = "exact"


@dataclass(frozen=True)
class QuantisationCondition:
    """One wall's quantisation condition.

    ``kind``: ``"crossing"`` (``average``: ``f_c >= required`` decides), ``"drift"`` (the wall's
    position sums rounded measurements: no ``f_c`` makes a spring passive) or ``"exact"`` (no
    quantum enters); ``holds``; ``required`` the least Coulomb friction (N, inf for a drift);
    ``leak_per_count`` the energy (J) the loop can return per count ``Delta`` of travel when the
    condition fails (0 when it holds, inf for a drift); ``quantum`` the resolution that enters
    (m for ``average``/``window``, m/s for ``point``/``lowpass``).
    """

    kind: str
    holds: bool
    required: float
    coulomb: float
    quantum: float
    leak_per_count: float
    velocity: str

    def describe(self) -> str:
        """One line for ``haptic-bus check`` and a gate's refusal."""
        verdict = "holds" if self.holds else "FAILS"
        unit = "m" if self.velocity.startswith(("average", "window")) else "m/s"
        if self.kind == EXACT:
            which = "Delta" if unit == "m" else "0x606C's quantum vq"
            return f"quantisation: holds (no wall, or {which} = {self.quantum:g} {unit} with {self.velocity} velocity)"
        if self.kind == DRIFT:
            unseen = {"average": "0x606C rounds the count difference (Delta/(T vq) is not whole), and the roundings "
                                 "of unequal count steps in and out never cancel",
                      "window": "a count that changes outside the window is never seen"}.get(
                self.velocity.partition(":")[0], "a creep slower than half the quantum is never seen")
            return (f"quantisation: {verdict}: the wall's position sums rounded {self.velocity} measurements "
                    f"(quantum {self.quantum:g} {unit}) and drifts: {unseen}, so a push of depth A and an unseen "
                    f"return hand back K A^2/2 against 2 f_c A of Coulomb friction (f_c = {self.coulomb:g} N): "
                    "no f_c makes a spring passive")
        leak = "" if self.holds else f"; it can leak {self.leak_per_count:.4g} J per crossing (per count of travel)"
        formula, quantum = _FORMULAS.get(self.velocity.partition(":")[0], ("B vq/2", "vq = {:g} m/s"))
        return (f"quantisation (per crossing, Abbott-Okamura with delay): {verdict}: Coulomb friction f_c = "
                f"{self.coulomb:g} N against the required {formula} = {self.required:.6g} N "
                f"({quantum.format(self.quantum)}){leak}")

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (infinities as None)."""
        return {"kind": self.kind, "holds": self.holds, "coulomb": self.coulomb, "required": _finite(self.required),
                "quantum": self.quantum, "leak_per_crossing": _finite(self.leak_per_count),
                "leak_units": "J per count of travel", "velocity": self.velocity}


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _counts_exactly(T: float, quantisation: Quantisation) -> bool:
    """0x606C holds the count difference over ``T`` exactly: ``Delta/(T vq)`` whole (or ``vq`` not given)."""
    if quantisation.velocity_resolution == 0.0:
        return True
    ratio = quantisation.position_resolution / (T * quantisation.velocity_resolution)
    return ratio >= 0.5 and abs(ratio - round(ratio)) <= 1e-9 * ratio


@dataclass(frozen=True)
class _Terms:
    """What a wall's quantisation condition is made of, for its velocity model: the ``quantum`` that
    enters (m for average and window, m/s for point and lowpass); the damper needs ``B quantum /
    divisor`` of Coulomb friction (``divisor`` the window or ``T``, s, or 2); a spring needs ``K quantum
    / 2`` (``spring``, average only) or ``drifts`` (no Coulomb friction makes it passive)."""

    quantum: float
    divisor: float
    spring: bool
    drifts: bool


def _terms(loop: WallLoop, quantisation: Quantisation) -> _Terms:
    """The terms of ``loop``'s condition (module docstring), one derivation for the verdict and the limits."""
    kind = loop.velocity.kind
    if kind in ("average", "window"):
        quantum, divisor = quantisation.position_resolution, loop.velocity.window(loop.T) or loop.T
    else:
        quantum, divisor = quantisation.velocity_resolution, 2.0
    average = kind == "average"
    return _Terms(quantum, divisor, average, not average or not _counts_exactly(loop.T, quantisation))


def quantisation_condition(loop: WallLoop, quantisation: Quantisation) -> QuantisationCondition:
    """The quantisation condition of the wall in ``loop`` with the device's ``quantisation``
    (see the module docstring): which quantum enters, the Coulomb friction it needs (N), the
    leak per count of travel (J) when it fails."""
    terms = _terms(loop, quantisation)
    f_c, K, B, quantum = quantisation.coulomb, loop.K, loop.B, terms.quantum
    name = str(loop.velocity)
    if quantum == 0.0 or (K == 0.0 and B == 0.0):
        return QuantisationCondition(EXACT, True, 0.0, f_c, quantum, 0.0, name)
    if K > 0.0 and terms.drifts:
        return QuantisationCondition(DRIFT, False, math.inf, f_c, quantum, math.inf, name)
    required = (K * quantum / 2.0 if terms.spring else 0.0) + B * quantum / terms.divisor
    holds = f_c >= required
    leak = 0.0 if holds else (required - f_c) * quantisation.position_resolution
    return QuantisationCondition(CROSSING, holds, required, f_c, quantum, leak, name)


def quantised_ceiling(loop: WallLoop, quantisation: Quantisation, parameter: str) -> float:
    """The largest ``parameter`` ("K" N/m at the loop's ``B``, or "B" N s/m at its ``K``) the
    quantisation condition admits (module docstring): ``inf`` where it admits any, 0 where only none
    (a spring that drifts), negative where not even 0 (the other parameter alone needs more Coulomb
    friction than the device has)."""
    terms = _terms(loop, quantisation)
    f_c, quantum = quantisation.coulomb, terms.quantum
    if quantum == 0.0:
        return math.inf
    per_damping = quantum / terms.divisor  # N of f_c per N s/m of B
    if parameter == "K":
        left = f_c - loop.B * per_damping  # what the damper leaves of f_c for the spring
        if terms.drifts:
            return 0.0 if left >= 0.0 else -1.0
        return 2.0 * left / quantum
    if terms.drifts and loop.K > 0.0:
        return -1.0
    spring = loop.K * quantum / 2.0 if terms.spring else 0.0
    return (f_c - spring) / per_damping
