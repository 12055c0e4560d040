"""Closed-loop poles of the wall loop and its stability: the zeros of the characteristic function.

The poles are ``z = 1 + w``, ``w`` the zeros of ``f(w) = (1 + w)^L A(w) + N(w) W(w)``
(:mod:`haptic_bus.analysis.characteristic`: every velocity model, every real delay, the delay
line a shift and the plant's order kept).  No polynomial in ``z`` is ever expanded.

**How they are found.**  For at most :data:`DENSE_LIMIT` poles the eigenvalues of ``M - I``
(:func:`~haptic_bus.analysis.sampled_loop.loop_matrix`, LAPACK ``geev``), which decide alone for
poles at least ``1e-6 sqrt(max|M - I|)`` from the circle and are the starting points for the others; for more
(a long delay) the ring ``z^L = -N W / A`` solved branch by branch, and the zeros of ``A``.
Then Newton steps on ``f`` itself (each accepted only if it lowers ``|f|``), and Aberth-Ehrlich
steps if two starting points ran into one zero -- ``O(L)`` work per step instead of the dense
solver's ``O(L^3)``: a delay of 1000 samples costs milliseconds, not seconds.

**How far to trust them.**  Each zero ``w_i`` comes with a first-order error bound
``8 eps size(w_i) / |f'(w_i)|`` (``size`` the magnitudes ``f`` is summed from).  The loop is
*stable* if every ``|z_i| - 1`` (formed without cancellation) is below minus its bound, *unstable*
if one is above its bound.  Otherwise -- a pole within round-off of the unit circle, e.g. a
handle of ``m = 1e8 kg`` sampled every ``2 ns`` whose poles sit ``1e-18`` inside it -- those
zeros are refined by Newton's method in 50-digit arithmetic (mpmath) on the same ``f`` with
the same double-precision inputs; a pole still within ``1e-40`` of the circle is *marginal*
(on it: the lossless oscillator, a wall exactly at its flip boundary), which the strict rule
does not call stable.

For the point model without delay the poles are the roots of
``(z - a)(z - 1) + k1 (K T z + B (z - 1))``; the seed's design gives 0.998 and 0.8014.
"""

from __future__ import annotations

import contextlib
import functools
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from haptic_bus.analysis.characteristic import (
    EPS,
    SCHUR_COHN_TRUST,
    Characteristic,
    characteristic,
    evaluate,
    schur_cohn,
)
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.sampled_loop import loop_matrix

DENSE_LIMIT = 96  # poles: up to this many, the dense eigenvalues give the starting points
_DENSE_TRUST = 1e-6  # |z| - 1 beyond this (times sqrt max |M - I|): a dense eigenvalue decides alone
_NEWTON_STEPS = 40
_ABERTH_STEPS = 60
_BOUND_FACTOR = 8.0
_SAFETY = 16.0  # a pole is decided only if |excess| exceeds this many times its bound
MP_DIGITS = 50
MARGINAL = 1e-40  # relative to |w|: a pole this close to the circle in 50 digits is on it

STABLE, MARGINAL_STATE, UNSTABLE = "stable", "marginal", "unstable"
_JUDGED_MAX = 4096
_judged: dict[WallLoop, bool] = {}  # loops whose poles were found: stable or not (what stable_all asks first)


def radius_excess(w: np.ndarray) -> np.ndarray:
    """``|1 + w| - 1`` without cancellation: ``(2 Re w + |w|^2) / (|1 + w| + 1)``."""
    w = np.asarray(w, dtype=complex)
    return (2.0 * w.real + np.abs(w) ** 2) / (np.abs(1.0 + w) + 1.0)


@dataclass(frozen=True)
class Stability:
    """The loop's poles judged against the unit circle.

    ``state``: ``"stable"`` (every pole strictly inside), ``"marginal"`` (none outside, one on
    the circle) or ``"unstable"``; ``excess`` the largest ``|z| - 1``; ``extended`` True when
    50-digit arithmetic decided it (double precision could not).
    """

    state: str
    excess: float
    extended: bool = False

    @property
    def stable(self) -> bool:
        """Every pole strictly inside the unit circle."""
        return self.state == STABLE

    @property
    def radius(self) -> float:
        """The largest pole magnitude (dimensionless)."""
        return 1.0 + self.excess


@dataclass(frozen=True)
class _Poles:
    w: np.ndarray  # largest |z| first
    bound: np.ndarray  # error bound of each |z| - 1
    stability: Stability


def _wall(loop: WallLoop) -> tuple[Characteristic, np.ndarray, bool]:
    char = characteristic(loop)
    integrator = loop.K > 0
    return char, char.wall(loop.kappa, loop.q, integrator), integrator


def _relative(f: np.ndarray, size: np.ndarray) -> np.ndarray:
    """``|f| / size``, and 0 where ``size`` is 0: every term ``f`` is formed from is 0 there (a
    wall and friction below the smallest double make ``w = 0`` an exact zero), so ``f`` is too."""
    return np.abs(f) / np.where(size > 0.0, size, 1.0)


def _newton(char: Characteristic, wall: np.ndarray, integrator: bool, w: np.ndarray, steps: int
            ) -> tuple[np.ndarray, np.ndarray]:
    """Guarded Newton steps on every zero at once (a step is taken only if it lowers ``|f|/size``);
    returns the zeros and whether each converged (to round-off, not stuck)."""
    w = w.copy()
    tolerance = (char.lag + 16) * EPS  # (1 + w)^L carries L roundings
    f, df, size = evaluate(char, wall, integrator, w)
    residual = _relative(f, size)
    converged = residual <= tolerance
    live = np.flatnonzero(~converged & (df != 0))
    f, df, residual = f[live], df[live], residual[live]
    for _ in range(steps):
        if live.size == 0:
            break
        with np.errstate(divide="ignore", invalid="ignore"):
            step = f / df
        trial = w[live] - step
        f2, df2, size2 = evaluate(char, wall, integrator, trial)
        residual2 = _relative(f2, size2)
        better = residual2 < residual
        w[live] = np.where(better, trial, w[live])
        small = np.abs(step) <= 4 * EPS * np.abs(trial)
        done = better & (small | (residual2 <= tolerance))
        converged[live[done]] = True
        keep = better & ~done & (df2 != 0)  # a step that does not help: stuck, left to Aberth
        live, f, df, residual = live[keep], f2[keep], df2[keep], residual2[keep]
    return w, converged


def _aberth(char: Characteristic, wall: np.ndarray, integrator: bool, w: np.ndarray, free: np.ndarray
            ) -> np.ndarray:
    """Aberth-Ehrlich steps on the zeros ``w[free]``, the others held: each free estimate is
    repelled by every other estimate, so it runs into a zero not yet found (``O(free L)`` a step)."""
    w = w.copy()
    index = np.flatnonzero(free)
    # break ties between free estimates that coincide
    w[index] += 1e-7 * max(float(np.max(np.abs(w))), 1e-3) * np.exp(2j * np.pi * np.arange(index.size) / max(index.size, 1))
    tolerance = (char.lag + 16) * EPS
    for _ in range(_ABERTH_STEPS):
        if index.size == 0:
            break
        f, df, size = evaluate(char, wall, integrator, w[index])
        diff = w[index][:, None] - w[None, :]
        diff[np.arange(index.size), index] = np.inf
        repulsion = np.sum(1.0 / diff, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = f / df
            step = ratio / (1.0 - ratio * repulsion)
        step = np.where(np.isfinite(step), step, 0.0)
        w[index] -= step
        moving = (np.abs(f) > tolerance * size) & (np.abs(step) > 4 * EPS * np.abs(w[index]))
        index = index[moving]
    return w


def _ring_starts(char: Characteristic, wall: np.ndarray, integrator: bool) -> np.ndarray:
    """Starting points for a long delay: ``z^L = -N W / A`` branch by branch, and ``A``'s zeros."""
    lag, a = char.lag, char.denominator(integrator)
    log_z = 1j * (2 * np.pi * np.arange(lag) + np.pi) / lag
    for _ in range(6):  # z <- z (h / z^L)^(1/L), the correction on the principal branch
        w = np.expm1(log_z)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = -np.polyval(char.numerator, w) * np.polyval(wall, w) / np.polyval(a, w)
        log_h = np.log(np.where(np.isfinite(h) & (h != 0), h, 1e-300))
        gap = log_h - lag * log_z
        gap = gap.real + 1j * np.angle(np.exp(1j * gap.imag))
        log_z = log_z + gap / lag
    plant = np.roots(a) if a.size > 1 else np.empty(0)
    return np.concatenate([np.expm1(log_z), plant.astype(complex)])


def _repeated(w: np.ndarray, window: int = 64) -> np.ndarray:
    """True for each estimate within 1e-10 (relative) of another one found before it in the order
    of real parts, among its ``window`` predecessors there (two estimates of one zero are neighbours)."""
    order = np.argsort(w.real, kind="stable")
    ranked = w[order]
    scale = np.maximum(np.abs(ranked), 1e-300)
    repeated = np.zeros(w.size, dtype=bool)
    for lag in range(1, min(window, w.size - 1) + 1):
        repeated[lag:] |= np.abs(ranked[lag:] - ranked[:-lag]) <= 1e-10 * scale[lag:]
    out = np.zeros(w.size, dtype=bool)
    out[order] = repeated
    return out


def _long_delay_zeros(char: Characteristic, wall: np.ndarray, integrator: bool, q: float) -> np.ndarray:
    """The zeros of ``f`` for a long delay: ring starts, Newton, Aberth for what Newton left."""
    origin = integrator and q == 0.0  # W = kappa (1 + w): z^L A and N W share the zero z = 0, taken out
    if origin:
        char, wall = replace(char, lag=char.lag - 1), wall[1:]
    w, converged = _newton(char, wall, integrator, _ring_starts(char, wall, integrator), _NEWTON_STEPS)
    free = ~converged | _repeated(w)
    if free.any():
        w, _ = _newton(char, wall, integrator, _aberth(char, wall, integrator, w, free), 2)
    return np.append(w, -1.0) if origin else w


def _zeros(loop: WallLoop) -> tuple[np.ndarray, np.ndarray]:
    """Every zero ``w`` of ``f`` and its first-order error bound."""
    if loop.K == 0.0 and loop.B == 0.0:  # no wall: the plant's own poles and a delay line of zeros (z = 0)
        char, _, integrator = _wall(loop)
        a = char.denominator(integrator)
        w = np.concatenate([np.roots(a).astype(complex) if a.size > 1 else np.empty(0), -np.ones(char.lag)])
        return w, np.zeros(w.size)
    if characteristic(loop).degree(loop.K > 0) <= DENSE_LIMIT:
        matrix = loop_matrix(loop)
        w = np.linalg.eigvals(matrix).astype(complex)
        # LAPACK's eigenvalues err by ~eps |M - I|, ~sqrt(eps |M - I|) at a double pole: far from the circle they decide
        near = np.abs(radius_excess(w)) < _DENSE_TRUST * math.sqrt(max(1.0, float(np.max(np.abs(matrix)))))
        if not near.any():
            return w, np.zeros(w.size)
        char, wall, integrator = _wall(loop)
        w[near], _ = _newton(char, wall, integrator, w[near], _NEWTON_STEPS)
    else:
        char, wall, integrator = _wall(loop)
        near = np.ones(char.degree(integrator), dtype=bool)
        w = _long_delay_zeros(char, wall, integrator, loop.q)
    bound = np.zeros(w.size)
    _, df, size = evaluate(char, wall, integrator, w[near])
    with np.errstate(divide="ignore", invalid="ignore"):  # 0/0 at a double zero of terms all 0: no bound, inf below
        first = _BOUND_FACTOR * EPS * size / np.abs(df)
    bound[near] = 2.0 * np.where(np.isfinite(first), first, np.inf) + 4 * EPS * (2 * np.abs(w[near].real) + np.abs(w[near]) ** 2)
    return w, bound


def _refine_extended(loop: WallLoop, w: np.ndarray) -> list[float]:
    """``|z| - 1`` of the zeros ``w`` refined by Newton's method in :data:`MP_DIGITS` digits."""
    import mpmath as mp  # type: ignore[import-untyped]  # no stubs; only here: a pole within round-off of the circle

    char, wall, integrator = _wall(loop)
    a = [mp.mpf(float(x)) for x in char.denominator(integrator)]
    numerator = [mp.mpf(float(x)) for x in char.numerator]
    wall_mp = [mp.mpf(float(x)) for x in wall]
    lag = char.lag
    out = []
    with mp.workdps(MP_DIGITS):
        def f(x: mp.mpc) -> mp.mpc:
            return mp.power(1 + x, lag) * _horner(a, x) + _horner(numerator, x) * _horner(wall_mp, x)

        for start in w:
            x = mp.mpc(complex(start))
            with contextlib.suppress(ValueError, ZeroDivisionError):  # no convergence: keep the double estimate
                x = mp.findroot(f, x, tol=mp.mpf(10) ** (-2 * MP_DIGITS + 10), maxsteps=200)
            excess = (2 * mp.re(x) + abs(x) ** 2) / (abs(1 + x) + 1)
            out.append(0.0 if abs(excess) <= MARGINAL * max(abs(x), abs(x) ** 2) else float(excess))
    return out


def _horner(coefficients: list[Any], x: Any) -> Any:
    """The polynomial with ``coefficients`` (highest power first) at ``x``, in ``x``'s arithmetic (Horner's rule).

    mpmath's ``polyval`` does the same, but its coefficient order changed in 1.4 (descending is
    deprecated, ``asc`` is unknown before it): the project supports both.
    """
    value = x * 0
    for c in coefficients:
        value = value * x + c
    return value


@functools.lru_cache(maxsize=1024)
def _poles(loop: WallLoop) -> _Poles:
    w, bound = _zeros(loop)
    excess = radius_excess(w)
    order = np.argsort(-excess, kind="stable")
    w, bound, excess = w[order], bound[order], excess[order]
    undecided = (np.abs(excess) <= _SAFETY * bound) & (bound > 0)  # a bound of 0: an exact zero
    decided = float(np.max(excess[~undecided], initial=-np.inf))
    if decided == 0.0 and not undecided.any():  # a pole exactly on the circle (the free mass's z = 1)
        stability = Stability(MARGINAL_STATE, 0.0)
    elif decided > 0.0 or not undecided.any():
        stability = Stability(STABLE if excess[0] < 0 else UNSTABLE, float(excess[0]))
    else:  # every pole not surely inside is within round-off of the circle: 50 digits decide
        refined = _refine_extended(loop, w[undecided])
        top = max(max(refined), decided)
        state = UNSTABLE if top > 0 else MARGINAL_STATE if top == 0.0 else STABLE
        stability = Stability(state, top, extended=True)
    w.setflags(write=False)
    bound.setflags(write=False)
    if len(_judged) >= _JUDGED_MAX:
        _judged.clear()
    _judged[loop] = stability.stable
    return _Poles(w, bound, stability)


def forget_walls() -> None:
    """Empty the per-wall cache of poles (a benchmark times a wall not judged before)."""
    _poles.cache_clear()
    _judged.clear()


def shifted_poles(loop: WallLoop) -> np.ndarray:
    """Closed-loop poles minus one, ``w = z - 1`` (complex), largest ``|z|`` first; accurate near ``z = 1``."""
    return _poles(loop).w


def closed_loop_poles(loop: WallLoop) -> np.ndarray:
    """The closed-loop poles in the z-plane (complex, sorted by decreasing magnitude)."""
    return 1.0 + _poles(loop).w


def stability(loop: WallLoop) -> Stability:
    """:class:`Stability` of ``loop``'s closed loop (see the module docstring)."""
    return _poles(loop).stability


def spectral_radius(loop: WallLoop) -> float:
    """Largest closed-loop pole magnitude (dimensionless); < 1 means stable."""
    return _poles(loop).stability.radius


def stable_all(loops: list[WallLoop]) -> list[bool]:
    """:func:`is_stable` of each loop, decided the cheapest way that is sure: the small ones' dense
    eigenvalues as one batch per matrix size, a long delay's by the Schur-Cohn recursion
    (:func:`~haptic_bus.analysis.characteristic.schur_cohn`), each where it is clearly inside or
    outside; else by :func:`stability`."""
    out: list[bool | None] = [_judged.get(loop) for loop in loops]
    by_size: dict[int, list[tuple[int, np.ndarray]]] = {}
    for i, loop in enumerate(loops):
        if out[i] is not None:
            continue
        char, wall, integrator = _wall(loop)
        if not np.any(wall):
            continue
        if char.degree(integrator) <= DENSE_LIMIT:
            matrix = loop_matrix(loop)
            by_size.setdefault(matrix.shape[0], []).append((i, matrix))
        else:
            margin = schur_cohn(char, wall, integrator)
            if abs(margin) > SCHUR_COHN_TRUST:
                out[i] = bool(margin > 0)
    for batch in by_size.values():
        matrices = np.stack([matrix for _, matrix in batch])
        excess = radius_excess(np.linalg.eigvals(matrices))
        trust = _DENSE_TRUST * np.sqrt(np.maximum(1.0, np.max(np.abs(matrices), axis=(1, 2))))
        outside = np.any(excess >= trust[:, None], axis=1)  # one pole clearly outside decides
        inside = np.all(excess <= -trust[:, None], axis=1)
        for (i, _), unstable, stable in zip(batch, outside, inside):
            if unstable or stable:
                out[i] = bool(stable)
    return [is_stable(loop) if known is None else known for loop, known in zip(loops, out)]


def is_stable(loop: WallLoop) -> bool:
    """True if every closed-loop pole is strictly inside the unit circle."""
    return _poles(loop).stability.stable
