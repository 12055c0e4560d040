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
from haptic_bus.analysis.theta_search import Group, Lane, refine_lanes, sorted_unique
from haptic_bus.analysis.trig import unit_point

DEFAULT_HARMONICS = 16
THETA_POINTS = 160
POINTS_PER_TURN = 24  # of the delay's e^{-j theta d} over (0, pi), as the criterion's grid
MAX_UNIFORM = 2048  # uniform points at most: the exposure of a long delay stays a report's cost
_LOWEST = 1e-6
_ROOT_STEPS = 60  # safeguarded Newton steps at most (a handful in practice)


@dataclass(frozen=True)
class Lifted:
    """``Herm(Tm) = diag(d) - (g x y^H + conj(g) y x^H)/2`` for each of ``n`` base frequencies, scaled
    by ``m/T``: ``d`` ``(n, K)``, ``x``, ``y`` ``(n, K)``, ``g`` ``(n,)``, ``K = 2N + 1`` harmonics
    ``-N..N`` (column ``N`` the base frequency itself)."""

    d: np.ndarray
    x: np.ndarray
    y: np.ndarray
    g: np.ndarray

    def matrices(self) -> np.ndarray:
        """The Hermitian matrices themselves, ``(n, K, K)``."""
        rank_two = self.g[:, None, None] * self.x[:, :, None] * self.y.conj()[:, None, :]
        return np.einsum("nk,kl->nkl", self.d, np.eye(self.d.shape[1])) - 0.5 * (rank_two + rank_two.conj().transpose(0, 2, 1))


def lifted(loop: WallLoop, theta: np.ndarray, harmonics: int) -> Lifted:
    """:class:`Lifted` at the base frequencies ``theta`` (rad, in (0, pi))."""
    theta = np.atleast_1d(np.asarray(theta, dtype=float))
    n = np.arange(-harmonics, harmonics + 1)
    thetas = theta[:, None] + 2 * np.pi * n[None, :]
    s = loop.c + 1j * thetas
    z, z_minus_1 = unit_point(theta)
    hold = (z_minus_1 / z)[:, None] / (1j * thetas)  # H(j omega_n)/T = (1 - z^-1)/(j theta_n)
    whole = np.exp(-1j * theta * loop.whole_delay)
    delayed = hold * np.exp(-1j * thetas * loop.fractional_delay) * whole[:, None]
    m_n = measurement_response(loop, thetas)
    g_md = pulse_transfer(period_map(loop), z, z_minus_1) * whole
    k_d = loop.kappa * z / z_minus_1 + loop.q
    gain = k_d / (1.0 + g_md * k_d)
    return Lifted((1.0 / s).real, delayed / s, (m_n / s).conj(), gain)


def _pair_least(lift: Lifted, centre: int) -> np.ndarray:
    """``(n, K)``: least eigenvalue of each pair (the base frequency and one alias); inf for the base itself."""
    x, y, g = lift.x, lift.y, lift.g[:, None]
    diagonal = lift.d - (g * x * y.conj()).real
    w = -0.5 * (g * x[:, centre:centre + 1] * y.conj() + (g * y[:, centre:centre + 1].conj() * x).conj())
    a = diagonal[:, centre:centre + 1]
    least = 0.5 * (a + diagonal) - np.sqrt(0.25 * (a - diagonal) ** 2 + np.abs(w) ** 2)
    least[:, centre] = np.inf
    return least


def _smaller(lift: Lifted, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The smaller eigenvalue of ``S = C^-1 + W^H (D - lam)^-1 W`` per row, and its derivative in ``lam``.

    ``Herm(Tm) = D + W C W^H``, ``W = [x, y]``, ``C = -[[0, g], [conj g, 0]]/2`` (indefinite).  For
    ``lam < min d``, ``S`` is 2 x 2 Hermitian and increases with ``lam``, so its smaller eigenvalue
    increases; it is 0 exactly at the least eigenvalue of ``Herm(Tm)`` and negative below it
    (Haynsworth's inertia formula: ``Herm(Tm) - lam`` has a negative eigenvalue iff ``S`` has two
    positive ones).
    """
    inverse = 1.0 / (lift.d - lam[:, None])
    square = inverse * inverse
    xx, yy, xy = np.abs(lift.x) ** 2, np.abs(lift.y) ** 2, lift.x.conj() * lift.y
    alpha, delta = np.sum(xx * inverse, axis=1), np.sum(yy * inverse, axis=1)
    off = np.sum(xy * inverse, axis=1) - 2.0 / lift.g.conj()  # C^-1 = -2 [[0, 1/conj(g)], [1/g, 0]]
    half_gap = 0.5 * (alpha - delta)
    radius = np.hypot(half_gap, np.abs(off))
    value = 0.5 * (alpha + delta) - radius
    # its derivative: u^H R' u for the unit eigenvector u of the smaller eigenvalue
    d_alpha, d_delta, d_off = np.sum(xx * square, axis=1), np.sum(yy * square, axis=1), np.sum(xy * square, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos2 = np.where(radius > 0, half_gap / radius, 0.0)
        sin2 = np.where(radius > 0, np.abs(off) / radius, 0.0)
        phase = np.where(np.abs(off) > 0, off / np.abs(off), 1.0)
    slope = 0.5 * (d_alpha + d_delta) - 0.5 * cos2 * (d_alpha - d_delta) - sin2 * (d_off * phase.conj()).real
    return value, slope


def _newton_root(lift: Lifted, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """The zero of :func:`_smaller` in each ``[low, high]`` (negative at ``low``, positive at ``high``).

    Each step fits ``e(lam) = a + b / (min d - lam)`` to the value and slope (the pole of the secular
    function, as LAPACK's ``dlaed4`` does) and takes its zero; a bisection step wherever that would
    leave the bracket.  Stops when no step moves by more than ``1e-15`` relative."""
    floor = np.min(lift.d, axis=1)
    lam, low, high = high.copy(), low.copy(), high.copy()
    live = np.arange(lam.size)  # the rows still moving: only they are evaluated
    part = lift
    for _ in range(_ROOT_STEPS):
        value, slope = _smaller(part, lam[live])
        x, lo, hi, pole = lam[live], low[live], high[live], floor[live]
        hi = np.where(value > 0, x, hi)
        lo = np.where(value < 0, x, lo)
        gap = pole - x
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            a = value - slope * gap
            trial = np.where(a < 0, pole + slope * gap * gap / a, x - value / slope)
        outside = ~np.isfinite(trial) | (trial <= lo) | (trial >= hi)
        trial = np.where(outside, 0.5 * (lo + hi), trial)
        moved = (np.abs(trial - x) > 1e-15 * np.abs(x)) & (value != 0)
        lam[live] = np.where(value == 0, x, trial)
        low[live], high[live] = lo, hi
        if not moved.all():
            live = live[moved]
            if not live.size:
                break
            part = _rows(lift, live)
    return lam


def least_eigenvalues(lift: Lifted, for_minimum: bool = False) -> np.ndarray:
    """The least eigenvalue of every lifted matrix, ``(n,)``.

    ``Herm(Tm)`` is a positive diagonal plus an indefinite rank-2 part, so at most one eigenvalue
    lies below ``min d``: the zero of :func:`_smaller` (increasing), bracketed by Weyl's lower bound
    ``min d + least eigenvalue of the rank-2 part`` and by the least eigenvalue of the worst pair
    (a principal 2 x 2: an upper bound), found by safeguarded Newton steps to round-off.  With
    equal diagonal entries (no friction: ``d = 0``) Weyl's bound is the value; where the pair's value
    is below ``min d`` and nothing is below it, the pair's value is.  The other rows (least
    eigenvalue at least about ``min d``) get LAPACK's ``eigvalsh`` -- or, ``for_minimum``, their lower
    bound ``min d`` where that is above the least value found exactly (a search for the minimum
    over the rows needs no more).
    """
    floor = np.min(lift.d, axis=1)
    lo = floor + _rank_two_least(-0.5 * lift.g[:, None] * lift.x, lift.y)
    flat = np.max(lift.d, axis=1) == floor
    pair = np.min(_pair_least(lift, lift.d.shape[1] // 2), axis=1)
    edge = floor - 1e-13 * np.maximum(np.abs(floor), np.abs(lo - floor))
    top = np.minimum(pair, edge)
    below = ~flat & (lift.g != 0)
    candidates = np.flatnonzero(below)
    if candidates.size:
        below[candidates] = _smaller(_rows(lift, candidates), top[candidates])[0] > 0
    out = np.where(flat, lo, np.where(~below & (pair < edge), pair, np.nan))  # not below the pair's value: it
    if below.any():
        out[below] = _newton_root(_rows(lift, below), np.minimum(lo[below], top[below]), top[below])
    rest = np.isnan(out)
    if for_minimum and rest.any():
        known = float(np.min(out[~rest])) if (~rest).any() else math.inf
        bounded = rest & (edge >= known)
        out[bounded] = edge[bounded]
        rest &= ~bounded
    if rest.any():
        out[rest] = np.linalg.eigvalsh(_rows(lift, rest).matrices())[:, 0]
    return out


def _rank_two_least(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The least eigenvalue of ``a y^H + y a^H`` per row: ``Re(y^H a) - sqrt(Re(y^H a)^2 + |r|^2 |y|^2)``
    with ``r`` the part of ``a`` orthogonal to ``y`` (Lagrange's identity: no cancellation in
    ``|a|^2 |y|^2 - |y^H a|^2``), and the difference rationalised where it would cancel."""
    yy = np.sum(np.abs(y) ** 2, axis=1)
    inner = np.sum(y.conj() * a, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = a - np.where(yy > 0, inner / yy, 0.0)[:, None] * y
    p = np.sum(np.abs(r) ** 2, axis=1) * yy
    root = np.sqrt(inner.real**2 + p)
    with np.errstate(divide="ignore", invalid="ignore"):
        rationalised = -p / (inner.real + root)
    return np.where(inner.real > 0, np.where(root > 0, rationalised, 0.0), inner.real - root)


def _rows(lift: Lifted, where: np.ndarray) -> Lifted:
    return Lifted(lift.d[where], lift.x[where], lift.y[where], lift.g[where])


def _least(loop: WallLoop, theta: np.ndarray, harmonics: int, pair: bool) -> np.ndarray:
    """Worst mean power (W per N^2) at each ``theta``: half the least eigenvalue of ``Herm(Tm)`` (or of the worst pair)."""
    lift = lifted(loop, theta, harmonics)
    value = np.min(_pair_least(lift, harmonics), axis=1) if pair else least_eigenvalues(lift, for_minimum=True)
    return 0.5 * loop.T / loop.m * value


def _worst_at(loop: WallLoop, theta: float, harmonics: int, pair: bool) -> tuple[float, np.ndarray, np.ndarray]:
    """(worst power in W per N^2, its harmonic numbers, the force's unit phasor vector) at ``theta``.

    The vector without a dense eigensolver: for the pair, the 2 x 2 closed form; for the
    harmonics, ``(D - lam)^-1 W u`` with ``u`` the null vector of ``S(lam)`` (:func:`_smaller`),
    when the least eigenvalue is below ``min d`` (else LAPACK's ``eigh``)."""
    lift = lifted(loop, np.array([theta]), harmonics)
    n = np.arange(-harmonics, harmonics + 1)
    if pair:
        k = int(np.argmin(_pair_least(lift, harmonics)[0]))
        herm = lift.matrices()[0][np.ix_([harmonics, k], [harmonics, k])]
        least = float(np.min(_pair_least(lift, harmonics)[0]))
        a, w = herm[0, 0].real, herm[0, 1]
        vector = np.array([w, least - a]) if abs(w) > 0 else np.array([1.0 + 0j, 0.0])
        return 0.5 * loop.T / loop.m * least, n[[harmonics, k]], vector / np.linalg.norm(vector)
    least = float(least_eigenvalues(lift)[0])
    if least < float(np.min(lift.d)) and lift.g[0] != 0:
        u = _null_vector(lift, least)
        vector = (lift.x[0] * u[0] + lift.y[0] * u[1]) / (lift.d[0] - least)
    else:
        values, vectors = np.linalg.eigh(lift.matrices()[0])
        least, vector = float(values[0]), vectors[:, 0]
    return 0.5 * loop.T / loop.m * least, n, vector / np.linalg.norm(vector)


def _null_vector(lift: Lifted, lam: float) -> np.ndarray:
    """The unit vector ``u`` with ``S(lam) u = 0`` (``S = C^-1 + W^H (D - lam)^-1 W``) for the first row."""
    inverse = 1.0 / (lift.d[0] - lam)
    alpha = float(np.sum(np.abs(lift.x[0]) ** 2 * inverse))
    delta = float(np.sum(np.abs(lift.y[0]) ** 2 * inverse))
    off = complex(np.sum(lift.x[0].conj() * lift.y[0] * inverse) - 2.0 / np.conj(lift.g[0]))
    matrix = np.array([[alpha, off], [np.conj(off), delta]])
    row = matrix[0] if abs(matrix[0, 0]) + abs(matrix[0, 1]) >= abs(matrix[1, 0]) + abs(matrix[1, 1]) else matrix[1]
    u = np.array([-row[1], row[0]])  # orthogonal to the larger row of a rank-1 matrix
    return u / np.linalg.norm(u)


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


def exposure_grid(loop: WallLoop, points: int = THETA_POINTS) -> np.ndarray:
    """The base frequencies searched (rad): ``points / 4`` logarithmic in [1e-6, 0.1], the rest uniform on
    (0, pi) -- more for a delay, :data:`POINTS_PER_TURN` per turn of ``e^{-j theta d}``, at most
    :data:`MAX_UNIFORM` (beyond ``D = 84`` samples the grid no longer sees every turn: a minimum
    narrower than ``pi / 2048`` between two grid points can be missed)."""
    uniform = min(max(points - points // 4, POINTS_PER_TURN * (math.ceil(loop.delay) + 1)), MAX_UNIFORM)
    return sorted_unique(np.concatenate([np.geomspace(_LOWEST, 0.1, points // 4),
                                         np.linspace(0.0, math.pi, uniform + 1)[1:-1]]))


def worst_force(loop: WallLoop, harmonics: int = DEFAULT_HARMONICS, pair: bool = False, points: int = THETA_POINTS
                ) -> Exposure:
    """The worst force made of ``theta``'s aliases up to ``harmonics`` (or the worst ``pair``), over ``theta``.

    All vectorised: the lifted matrices of every ``theta`` at once, their least eigenvalues by the
    secular equation (:func:`least_eigenvalues`, exact to round-off), ``theta`` on
    :func:`exposure_grid`, its three lowest local minima zoomed by
    :func:`~haptic_bus.analysis.theta_search.refine_lanes` (the worst base frequency to ~1e-7 of
    a grid step; the value is smooth in ``theta``).  The worst at the grid's ends (``1e-6`` rad,
    just below ``pi``) stands for the limit there.
    """
    grid = exposure_grid(loop, points)
    group = Group(lambda theta: _least(loop, theta, harmonics, pair), shared=False)
    [best] = refine_lanes(grid, [Lane(group.evaluate(grid), "power", lambda part: part)], {"power": group},
                          lambda theta: None)
    power, n, vector = _worst_at(loop, best.theta, harmonics, pair)
    freqs, amps, phases = _force(loop, best.theta, n, vector)
    return Exposure(power, best.theta, harmonics, freqs, amps, phases)


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
