"""Out-of-band exposure: what an operator force with content above Nyquist can extract (DESIGN 3.4).

The exact criterion speaks of operator forces band-limited below ``pi/T``.  Above it, a tone at
``omega`` and its aliases ``omega + 2 pi n/T`` meet in the same samples, and a force that pairs
them can be answered by a wall force that pushes energy out even where every single tone sees
``Re T_fund >= 0``.

**Harmonic (lifted) analysis.**  Take an operator force made of the aliases of one
``theta = omega T`` in (0, pi): ``w(t) = Re sum_n W_n e^{j omega_n t}``, ``omega_n = (theta + 2 pi n)/T``,
``n = -N..N``.  The sampled loop sees one discrete frequency, so (all admittances in m/(N s))

    V_n = G11_n (W_n - h_n U),   U = K_d Y,   Y = sum_m M_m V_m,
    =>  V = Tm W,   Tm = diag(G11_n) - (G11_n h_n) (K_d / (1 + G_md K_d)) (M_m G11_m)^T,

with ``h_n = (H(j omega_n)/T) e^{-j omega_n D T}`` the held, delayed force's ``n``-th harmonic,
``M_n`` the velocity model's response and ``G_md`` the *exact* sampled map (every alias, not
just the ``2N + 1`` kept).  The mean power the operator puts in is
``P = Re(W^H V)/2 = W^H Herm(Tm) W / 2``: the worst over forces of unit size
``sum |W_n|^2 = 1 N^2`` is half the least eigenvalue of the Hermitian part, and over ``theta``
its minimum.  Truncating at ``N`` harmonics restricts the forces, so the value decreases with
``N`` and converges (:func:`exposure_convergence`); ``N = 0`` is the band-limited
``min Re T_fund / 2``.  The worst *pair* (a tone below Nyquist and one alias) is the ``2 x 2``
case, reported with its two frequencies in Hz.  :func:`confirm_by_simulation` runs the pair
through the exact time-domain loop (:func:`haptic_bus.analysis.energy.periodic_mean_power`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.sampled_loop import measurement_response, period_map, pulse_transfer
from haptic_bus.analysis.trig import unit_point

DEFAULT_HARMONICS = 16
THETA_POINTS = 160
_GOLDEN_STEPS = 40  # the bracket shrinks to 0.618^40 = 4e-9 of its size
_LOWEST = 1e-6


def _lifted(loop: WallLoop, theta: float, harmonics: int) -> tuple[np.ndarray, np.ndarray]:
    """``(n, Herm(Tm))`` at ``theta`` for ``n = -N..N``: scaled by ``m/T`` (dimensionless)."""
    n = np.arange(-harmonics, harmonics + 1)
    thetas = theta + 2 * np.pi * n
    s = loop.c + 1j * thetas
    z, z_minus_1 = unit_point(np.array([theta]))
    hold = (1.0 - 1.0 / z[0]) / (1j * thetas)  # H(j omega_n)/T
    delayed = hold * np.exp(-1j * thetas * loop.fractional_delay) * np.exp(-1j * theta * loop.whole_delay)
    m_n = measurement_response(loop, thetas)
    g_md = pulse_transfer(period_map(loop), z, z_minus_1)[0] * np.exp(-1j * theta * loop.whole_delay)
    k_d = loop.kappa * z[0] / z_minus_1[0] + loop.q
    gain = k_d / (1.0 + g_md * k_d)
    left, right = delayed / s, m_n / s
    tm = np.diag(1.0 / s) - gain * np.outer(left, right)
    return n, 0.5 * (tm + tm.conj().T)


@dataclass(frozen=True)
class Exposure:
    """The worst mean power (W per N^2 of operator force, ``sum |W_n|^2 = 1``) from aliases of one frequency.

    ``power < 0``: the loop hands that much energy per second to the operator.  ``theta``
    (rad) the base frequency, ``harmonics`` the ``N`` used, ``frequencies`` (Hz) and
    ``amplitudes``/``phases`` (N, rad, for ``w = sum A sin(2 pi f t + phase)``) of the worst force.
    """

    power: float
    theta: float
    harmonics: int
    frequencies: tuple[float, ...]
    amplitudes: tuple[float, ...]
    phases: tuple[float, ...]

    @property
    def extractable(self) -> float:
        """``max(0, -power)``: W per N^2 the operator can take out."""
        return max(0.0, -self.power)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready."""
        return {"power": self.power, "extractable": self.extractable, "theta": self.theta, "harmonics": self.harmonics,
                "frequencies_hz": list(self.frequencies), "amplitudes_n": list(self.amplitudes),
                "phases_rad": list(self.phases)}


def _force(loop: WallLoop, theta: float, n: np.ndarray, vector: np.ndarray) -> tuple[tuple[float, ...], ...]:
    """The real force ``Re sum W_n e^{j omega_n t}`` as tones ``A sin(2 pi f t + phase)``, strongest first."""
    keep = np.abs(vector) > 1e-12 * np.max(np.abs(vector))
    freqs, amps, phases = [], [], []
    for k, w in zip(n[keep], vector[keep]):
        omega = (theta + 2 * np.pi * k) / loop.T
        phase = float(np.angle(w)) if omega >= 0 else -float(np.angle(w))
        freqs.append(abs(omega) / (2 * np.pi))
        amps.append(float(abs(w)))
        phases.append(phase + 0.5 * math.pi)  # Re(W e^{j omega t}) = |W| sin(omega t + arg W + pi/2)
    order = np.argsort(amps)[::-1]
    return tuple(tuple(float(x[i]) for i in order) for x in (freqs, amps, phases))


def _pair_least(herm: np.ndarray, centre: int) -> np.ndarray:
    """Least eigenvalue of every pair ``[[a, w], [conj w, e]]`` of ``theta`` (index ``centre``) and one alias."""
    a, e, w = herm[centre, centre].real, np.diag(herm).real, herm[centre]
    least = 0.5 * (a + e) - np.sqrt(0.25 * (a - e) ** 2 + np.abs(w) ** 2)
    least[centre] = np.inf
    return least


def _least(loop: WallLoop, theta: float, harmonics: int, pair: bool) -> float:
    """Worst mean power (W per N^2) at ``theta``: half the least eigenvalue of ``Herm(Tm)`` (or of the worst pair)."""
    herm = _lifted(loop, theta, harmonics)[1]
    value = np.min(_pair_least(herm, harmonics)) if pair else np.linalg.eigvalsh(herm)[0]
    return 0.5 * loop.T / loop.m * float(value)


def _worst_at(loop: WallLoop, theta: float, harmonics: int, pair: bool) -> tuple[float, np.ndarray, np.ndarray]:
    """(worst power in W per N^2, its harmonic numbers, the force's unit phasor vector) at ``theta``."""
    n, herm = _lifted(loop, theta, harmonics)
    if pair:
        idx = np.array([harmonics, int(np.argmin(_pair_least(herm, harmonics)))])
        n, herm = n[idx], herm[np.ix_(idx, idx)]
    values, vectors = np.linalg.eigh(herm)
    return 0.5 * loop.T / loop.m * float(values[0]), n, vectors[:, 0]


def worst_force(loop: WallLoop, harmonics: int = DEFAULT_HARMONICS, pair: bool = False, points: int = THETA_POINTS
                ) -> Exposure:
    """The worst force made of ``theta``'s aliases up to ``harmonics`` (or the worst ``pair``), over ``theta``.

    ``theta`` on a logarithmic-plus-uniform grid of ``points`` points of [1e-6, pi), the best
    refined by golden section (the value is smooth in ``theta``).
    """
    grid = np.unique(np.concatenate([np.geomspace(_LOWEST, 0.1, points // 4),
                                     np.linspace(0.0, math.pi, points - points // 4 + 1)[1:-1]]))
    def f(t: float) -> float:
        return _least(loop, t, harmonics, pair)

    values = [f(t) for t in grid]
    i = int(np.argmin(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    ratio = (math.sqrt(5) - 1) / 2
    a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    fa, fb = f(a), f(b)
    for _ in range(_GOLDEN_STEPS):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - ratio * (hi - lo)
            fa = f(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + ratio * (hi - lo)
            fb = f(b)
    theta = min([(a, fa), (b, fb), (float(grid[i]), values[i])], key=lambda pair_: pair_[1])[0]
    power, n, vector = _worst_at(loop, theta, harmonics, pair)
    freqs, amps, phases = _force(loop, theta, n, vector)
    return Exposure(power, theta, harmonics, freqs, amps, phases)


def exposure_convergence(loop: WallLoop, harmonics: tuple[int, ...] = (0, 1, 2, 4, 8, 16, 32, 64)) -> list[Exposure]:
    """:func:`worst_force` for increasing ``N``: nonincreasing, converging (``N = 0``: below Nyquist only)."""
    return [worst_force(loop, n) for n in harmonics]


def exposure_at(loop: WallLoop, theta: float, harmonics: int = DEFAULT_HARMONICS, pair: bool = False) -> Exposure:
    """The worst force made of the aliases of one given ``theta`` (rad), without the search over ``theta``."""
    power, n, vector = _worst_at(loop, theta, harmonics, pair)
    freqs, amps, phases = _force(loop, theta, n, vector)
    return Exposure(power, theta, harmonics, freqs, amps, phases)


def confirm_by_simulation(loop: WallLoop, exposure: Exposure, samples: int) -> float:
    """The mean power (W) of ``exposure``'s force in the exact time-domain loop's periodic steady state.

    ``exposure.theta`` must be ``2 pi p / samples`` (all its tones then repeat after ``samples``
    periods); compare with ``exposure.power`` (the force has ``sum A^2 = 1`` N^2).
    """
    from haptic_bus.analysis.energy import Tones, periodic_mean_power

    tones = Tones(tuple(2 * np.pi * f for f in exposure.frequencies), exposure.amplitudes, exposure.phases)
    return periodic_mean_power(loop, tones, samples)
