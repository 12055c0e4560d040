"""Several axes under one wall: the linear, in-contact loop of a Cartesian device, and its poles.

A Cartesian device has ``N`` axes, each its own drive: axis ``i`` is the 1-D handle of
:class:`~haptic_bus.analysis.loop.WallLoop` (mass ``m_i`` kg, friction ``b_i`` N s/m, the velocity
model of its drive, its loop delay ``D_i`` samples), all sampled at one SYNC every ``T`` s.
The wall couples them: the controller reads every axis' velocity ``y_k`` (m/s), integrates
``x_k = x_{k-1} + T y_k`` and sends

    u_k = K x_k + B y_k          (N, one entry per axis; axis i applies u_i after its own D_i)

with ``K`` (N/m) and ``B`` (N s/m) real symmetric positive semidefinite ``N x N`` matrices: a
plane wall with unit normal ``n`` is ``K n n^T``, ``B n n^T`` (:func:`plane_wall`), a corner
where two planes act at once their sum.  Each axis' plant and measurement are exactly the 1-D
ones; only the wall mixes the axes.

**Components.**  Axes that no off-diagonal entry of ``K`` or ``B`` links are independent loops:
:func:`components` splits the axes into the connected groups of that graph.  A group of one
axis is today's 1-D loop ``WallLoop(m_i, b_i, T, K_ii, B_ii, D_i, velocity_i)``, judged by
the 1-D criterion unchanged (an axis-aligned wall, or a free axis, reduces to it exactly).

**The closed loop of a group** (:func:`coupled_loop_matrix`), built from the 1-D pieces: each
axis contributes the block :func:`~haptic_bus.analysis.sampled_loop.shifted_closed_loop` of its
own period map with no wall (plant, measurement, and the register of its held forces
``u_{i,k-1} .. u_{i,k-L_i}``), in its own scaled units (force ``u_i T/m_i``); the controller's
integrator is kept only along the range of ``K`` (``K = V diag(lambda) V^T`` from ``eigh``,
eigenvalues below ``1e-12`` of the largest dropped: ``xi_k = V^T x_k / T``, one state per
stiff direction -- a plane wall has one, its depth), because the other integrator directions
feed nothing back (their ``z = 1`` modes are no poles of the loop).  The wall force row of axis
``i`` over the whole state is

    u_i T/m_i = (T/m_i) sum_j (T K_ij + B_ij) y_j + (T^2/m_i) (V diag(lambda))_i . xi_{k-1},

added where the 1-D block uses its own ``u_k``: the plant's rows when ``d_i = 0`` (the force
acts in the same period), the first register slot otherwise.  For one axis this is the 1-D
matrix entry for entry.  Poles: eigenvalues ``w`` of ``M - I``, ``z = 1 + w``
(:func:`coupled_shifted_poles`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.loop import DAMPING_RANGE, STIFFNESS_RANGE, WallLoop
from haptic_bus.analysis.poles import radius_excess
from haptic_bus.analysis.sampled_loop import ClosedLoopLayout, period_map, shifted_closed_loop
from haptic_bus.errors import ParameterError

MAX_AXES = 6
RANK_TOLERANCE = 1e-12
"""Stiffness directions below this fraction of the largest carry no integrator (below what
the double-precision loop resolves)."""
_SYMMETRY_TOLERANCE = 1e-12


def _matrix(name: str, value: ArrayLike, size: int, ceiling: float, unit: str) -> np.ndarray:
    """A real symmetric positive semidefinite ``size x size`` matrix with entries in range, else ParameterError."""
    matrix = np.array(value, dtype=float)
    if matrix.shape != (size, size):
        raise ParameterError(name, f"shape {matrix.shape}", f"a {size} x {size} matrix ({unit}), one row per axis")
    if not np.all(np.isfinite(matrix)) or np.max(np.abs(matrix), initial=0.0) > ceiling:
        raise ParameterError(name, matrix.tolist(), f"finite entries of magnitude <= {ceiling:g} {unit}")
    scale = max(float(np.max(np.abs(matrix))), 1e-300)
    if np.max(np.abs(matrix - matrix.T)) > _SYMMETRY_TOLERANCE * scale:
        raise ParameterError(name, matrix.tolist(), "a symmetric matrix (a wall stores energy, it does not circulate it)")
    matrix = 0.5 * (matrix + matrix.T)
    if size and float(np.linalg.eigvalsh(matrix)[0]) < -_SYMMETRY_TOLERANCE * scale:
        raise ParameterError(name, matrix.tolist(), f"a positive semidefinite matrix ({unit}): no negative stiffness or damping")
    matrix.setflags(write=False)
    return matrix


def unit_normal(normal: ArrayLike, size: int) -> np.ndarray:
    """``normal`` scaled to unit length (a ``size``-vector, finite, not zero), else ParameterError."""
    n = np.array(normal, dtype=float)
    if n.shape != (size,) or not np.all(np.isfinite(n)) or not np.any(n):
        raise ParameterError("normal", np.asarray(normal).tolist(), f"a finite nonzero vector of {size} components, one per axis")
    length = math.hypot(*n)
    return n / length


@dataclass(frozen=True, eq=False)
class CoupledLoop:
    """The axes (each a :class:`WallLoop` whose own ``K``, ``B`` are 0: device, velocity model,
    delay) and the wall matrices ``K`` (N/m) and ``B`` (N s/m) acting on them; one period ``T``."""

    axes: tuple[WallLoop, ...]
    K: np.ndarray
    B: np.ndarray

    def __post_init__(self) -> None:
        axes = tuple(self.axes)
        if not 1 <= len(axes) <= MAX_AXES or not all(isinstance(a, WallLoop) for a in axes):
            raise ParameterError("axes", len(axes), f"1 to {MAX_AXES} axes, each a WallLoop")
        if any(a.K != 0.0 or a.B != 0.0 for a in axes):
            raise ParameterError("axes", "a wall on an axis", "axes with K = B = 0: the wall is the K and B matrices")
        periods = {a.T for a in axes}
        if len(periods) != 1:
            raise ParameterError("T", sorted(periods), "one period for every axis (one SYNC)")
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "K", _matrix("K", self.K, len(axes), STIFFNESS_RANGE[1], "N/m"))
        object.__setattr__(self, "B", _matrix("B", self.B, len(axes), DAMPING_RANGE[1], "N s/m"))

    @property
    def size(self) -> int:
        """Number of axes ``N``."""
        return len(self.axes)

    @property
    def T(self) -> float:
        """The common period (s)."""
        return self.axes[0].T

    def part(self, indices: list[int]) -> CoupledLoop:
        """The loop of the axes ``indices`` alone (their rows and columns of ``K`` and ``B``)."""
        pick = np.ix_(indices, indices)
        return CoupledLoop(tuple(self.axes[i] for i in indices), self.K[pick], self.B[pick])

    def axis_loop(self, i: int) -> WallLoop:
        """Axis ``i`` with its diagonal wall ``(K_ii, B_ii)``: the 1-D loop it is when nothing couples it."""
        return self.axes[i].with_wall(float(self.K[i, i]), float(self.B[i, i]))

    def scaled(self, stiffness: float, damping: float) -> CoupledLoop:
        """The same axes with ``K`` times ``stiffness`` and ``B`` times ``damping`` (dimensionless, >= 0)."""
        return CoupledLoop(self.axes, self.K * stiffness, self.B * damping)

    def describe(self) -> str:
        """One line per axis (m, b, delay, velocity) for messages."""
        return "; ".join(f"axis {i}: m = {a.m:g} kg, b = {a.b:g} N s/m, D = {a.delay:g}, velocity {a.velocity}"
                         for i, a in enumerate(self.axes))


def plane_wall(axes: tuple[WallLoop, ...], normal: ArrayLike, K: float, B: float) -> CoupledLoop:
    """The loop of a plane wall with unit normal ``normal`` (any nonzero vector, normalised):
    ``K n n^T`` (N/m), ``B n n^T`` (N s/m)."""
    n = unit_normal(normal, len(axes))
    outer = np.outer(n, n)
    return CoupledLoop(tuple(axes), K * outer, B * outer)


def components(loop: CoupledLoop) -> list[list[int]]:
    """The groups of axes the wall links (connected through nonzero off-diagonal ``K`` or ``B``), ascending."""
    linked = (loop.K != 0.0) | (loop.B != 0.0)
    group = list(range(loop.size))

    def root(i: int) -> int:
        while group[i] != i:
            i = group[i]
        return i

    for i, j in zip(*np.nonzero(linked)):
        group[root(int(i))] = root(int(j))
    found: dict[int, list[int]] = {}
    for i in range(loop.size):
        found.setdefault(root(i), []).append(i)
    return sorted(found.values())


def stiff_directions(K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(V, lambda)`` with ``K = V diag(lambda) V^T`` over the stiff directions (``lambda > 1e-12 max``)."""
    values, vectors = np.linalg.eigh(K)
    keep = values > RANK_TOLERANCE * max(float(values[-1]), 0.0)
    return vectors[:, keep], values[keep]


def coupled_loop_matrix(loop: CoupledLoop) -> np.ndarray:
    """``M - I`` of the coupled closed loop ``xi_{k+1} = M xi_k`` (module docstring), dimensionless."""
    T = loop.T
    pmaps = [period_map(axis) for axis in loop.axes]
    blocks = [shifted_closed_loop(p, 0.0, 0.0, axis.delay, integrator=False) for p, axis in zip(pmaps, loop.axes)]
    layouts = [ClosedLoopLayout(p, 0.0, 0.0, axis.delay, integrator=False) for p, axis in zip(pmaps, loop.axes)]
    V, stiffness = stiff_directions(loop.K)
    starts = np.cumsum([0] + [b.shape[0] for b in blocks])
    first_integrator = int(starts[-1])
    size = first_integrator + stiffness.size
    shifted = np.zeros((size, size))
    measured = np.zeros((loop.size, size))  # y_j as rows over the state
    for j, (block, pmap) in enumerate(zip(blocks, pmaps)):
        at = slice(int(starts[j]), int(starts[j + 1]))
        shifted[at, at] = block
        measured[j, int(starts[j]) : int(starts[j]) + pmap.c.size] = pmap.c
    shifted[first_integrator:] = V.T @ measured  # xi_k = xi_{k-1} + V^T y_k
    for i, (axis, pmap, lay) in enumerate(zip(loop.axes, pmaps, layouts)):
        row = (T / axis.m) * ((T * loop.K[i] + loop.B[i]) @ measured)
        row[first_integrator:] += (T * T / axis.m) * (V[i] * stiffness)
        start = int(starts[i])
        if lay.d == 0:  # u_k acts in this period: the wall force opposes the motion
            shifted[start : start + lay.n] -= np.outer(pmap.gamma_now, row)
        if lay.slots:
            shifted[start + lay.first_slot] += row
    return shifted


def coupled_shifted_poles(loop: CoupledLoop) -> np.ndarray:
    """Closed-loop poles minus one, ``w = z - 1`` (complex), largest ``|z|`` first."""
    w = np.linalg.eigvals(coupled_loop_matrix(loop))
    return w[np.argsort(-radius_excess(w), kind="stable")]


def coupled_poles(loop: CoupledLoop) -> np.ndarray:
    """The coupled loop's closed-loop poles in the z-plane, largest magnitude first."""
    return 1.0 + coupled_shifted_poles(loop)
