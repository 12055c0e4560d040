"""Benchmark 2: simulating the plant in the closed loop, run time against trajectory error.

The run: a desktop-class handle (``m = 0.032 kg``, ``b = 3.62 N s/m``, ``T = 1 ms``, so
``c = bT/m = 0.11``) in a CiA-402 loop (delay ``d = 1``) with a unilateral wall at 1 mm
(``K = 400 N/m``, ``B = 1 N s/m``); the operator pushes 1 N from rest at ``t = 0`` and lets go
at ``t = 250 ms`` (a sample instant); the run ends at ``400 ms`` (the smoke run: 100 ms and 200 ms).  Each period the controller
samples ``v_k``, integrates ``x_k = x_{k-1} + T v_k`` and computes
``u_k = K (x_k - 1 mm) + B v_k`` while ``x_k > 1 mm`` (else 0); the drive holds ``u_{k-1}``.
Between samples every force is constant, so the plant ``m dv/dt + b v = w - u`` has an exact
solution there: the exact ZOH step (:class:`haptic_bus.analysis.plant.ExactPlant`) has no truncation
error at all.  (A smoothly varying operator force would give every method, ZOH included, an
``O(h^2)`` hold error; not measured here.)

Methods, each integrating the handle's velocity and true position over every period:
the exact ZOH step; forward Euler and classic RK4 with 1..1000 equal sub-steps;
``scipy.integrate.solve_ivp`` (RK45 and DOP853) restarted every period (the wall force jumps
at the samples) at several tolerances (``rtol = tol``, ``atol = tol * 1e-3`` in m and m/s).
Reference: the same loop in mpmath at 40 digits with the exact solution.  Error: the largest
deviation over all samples of velocity (relative to the largest speed) or position (relative to
the largest excursion), whichever is larger.  Time: per simulated second (median, min-max of 5 repeats).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.analysis.plant import ExactPlant
from haptic_bus.bench.size import Size
from haptic_bus.bench.timing import time_per_call


@dataclass(frozen=True)
class Scenario:
    """The contact run (SI units); see the module docstring."""

    m: float = 0.032  # kg
    b: float = 3.62  # N s/m
    T: float = 1e-3  # s
    K: float = 400.0  # N/m
    B: float = 1.0  # N s/m
    wall_at: float = 1e-3  # m
    delay: int = 1  # samples
    push: float = 1.0  # N
    release_sample: int = 250
    samples: int = 400

    @property
    def duration(self) -> float:
        """Simulated time in s."""
        return self.samples * self.T


Stepper = Callable[[float, float, float], tuple[float, float]]  # (v, p, force) -> (v, p) after T


def run_loop(s: Scenario, step: Stepper) -> tuple[np.ndarray, np.ndarray]:
    """The closed loop with ``step`` advancing the plant over one period; (v_k, p_k) at samples."""
    v = p = x = 0.0
    pending = [0.0] * s.delay
    vs = np.empty(s.samples + 1)
    ps = np.empty(s.samples + 1)
    for k in range(s.samples):
        vs[k], ps[k] = v, p
        x += s.T * v
        pending.append(s.K * (x - s.wall_at) + s.B * v if x > s.wall_at else 0.0)
        force = (s.push if k < s.release_sample else 0.0) - pending.pop(0)
        v, p = step(v, p, force)
    vs[-1], ps[-1] = v, p
    return vs, ps


def exact_stepper(s: Scenario) -> Stepper:
    """The exact ZOH step (:class:`ExactPlant`)."""
    plant = ExactPlant(s.m, s.b, s.T)

    def step(v: float, p: float, force: float) -> tuple[float, float]:
        plant.velocity, plant.position = v, p
        plant.advance(force)
        return plant.velocity, plant.position

    return step


def euler_stepper(s: Scenario, substeps: int) -> Stepper:
    """Forward Euler, ``substeps`` equal steps per period."""
    h, m, b = s.T / substeps, s.m, s.b

    def step(v: float, p: float, force: float) -> tuple[float, float]:
        for _ in range(substeps):
            p += h * v
            v += h * (force - b * v) / m
        return v, p

    return step


def rk4_stepper(s: Scenario, substeps: int) -> Stepper:
    """Classic RK4 on (p, v), ``substeps`` equal steps per period."""
    h, m, b = s.T / substeps, s.m, s.b

    def step(v: float, p: float, force: float) -> tuple[float, float]:
        for _ in range(substeps):
            a1 = (force - b * v) / m
            v2 = v + 0.5 * h * a1
            a2 = (force - b * v2) / m
            v3 = v + 0.5 * h * a2
            a3 = (force - b * v3) / m
            v4 = v + h * a3
            a4 = (force - b * v4) / m
            p += h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
            v += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return v, p

    return step


def ivp_stepper(s: Scenario, method: str, tol: float) -> Stepper:
    """``scipy.integrate.solve_ivp`` over each period with the held force."""
    from scipy.integrate import solve_ivp

    m, b, span = s.m, s.b, (0.0, s.T)

    def step(v: float, p: float, force: float) -> tuple[float, float]:
        sol = solve_ivp(lambda t, y: (y[1], (force - b * y[1]) / m), span, (p, v), method=method,
                        rtol=tol, atol=tol * 1e-3)
        return float(sol.y[1, -1]), float(sol.y[0, -1])

    return step


def mp_reference(s: Scenario, digits: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """The loop with the exact solution in mpmath at ``digits`` digits; (v_k, p_k) as floats."""
    import mpmath as mp  # type: ignore[import-untyped]  # no stubs

    with mp.workdps(digits):
        m, b, T, K, B, wall = (mp.mpf(x) for x in (s.m, s.b, s.T, s.K, s.B, s.wall_at))
        a = mp.exp(-b * T / m)
        decay = -mp.expm1(-b * T / m)  # 1 - a
        v = p = x = mp.mpf(0)
        pending = [mp.mpf(0)] * s.delay
        vs, ps, margin = [], [], mp.inf
        for k in range(s.samples):
            vs.append(v)
            ps.append(p)
            x += T * v
            margin = min(margin, abs(x - wall))
            pending.append(K * (x - wall) + B * v if x > wall else mp.mpf(0))
            force = (mp.mpf(s.push) if k < s.release_sample else mp.mpf(0)) - pending.pop(0)
            terminal = force / b
            p = p + (m / b) * decay * (v - terminal) + terminal * T
            v = a * v + decay * terminal
        vs.append(v)
        ps.append(p)
        if margin < mp.mpf("1e-9"):
            raise ArithmeticError("the reference grazes the wall's switching point; choose another scenario")
        return np.array([float(x) for x in vs]), np.array([float(x) for x in ps])


def trajectory_error(run: tuple[np.ndarray, np.ndarray], ref: tuple[np.ndarray, np.ndarray]) -> float:
    """max(|dv|/max|v_ref|, |dp|/max|p_ref|) over the samples (dimensionless)."""
    v, p = run
    v_ref, p_ref = ref
    return float(max(np.max(np.abs(v - v_ref)) / np.max(np.abs(v_ref)), np.max(np.abs(p - p_ref)) / np.max(np.abs(p_ref))))


SMOKE_SCENARIO = Scenario(release_sample=100, samples=200)  # the smoke run's: the handle is at rest in the wall
# 3.5 mm deep by 100 ms (speed below 1e-4 m/s) and out of it, at rest again, 50 ms after the release, so push, contact,
# rest, release and rebound all happen in half the samples (each method's 7 runs of solve_ivp per period are most of
# the section's CPU)


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 2; returns its section of ``bench.json``."""
    s = size.pick(SMOKE_SCENARIO, Scenario(), Scenario())
    ref = mp_reference(s)
    substeps = size.pick((1, 10), (1, 10, 100, 1000), (1, 10, 100, 1000))
    tolerances = size.pick((1e-3,), (1e-3, 1e-6, 1e-9), (1e-3, 1e-6, 1e-9, 1e-12))
    cases: list[tuple[str, str, float, Stepper]] = [("exact ZOH", "exact", 1, exact_stepper(s))]
    cases += [(f"Euler x{n}", "euler", n, euler_stepper(s, n)) for n in substeps]
    cases += [(f"RK4 x{n}", "rk4", n, rk4_stepper(s, n)) for n in substeps]
    for method in ("RK45", "DOP853"):
        cases += [(f"solve_ivp {method} tol {tol:g}", f"ivp_{method}", tol, ivp_stepper(s, method, tol)) for tol in tolerances]
    rows: list[dict[str, Any]] = []
    for name, family, parameter, stepper in cases:
        result = run_loop(s, stepper)
        error = trajectory_error(result, ref)
        per_second = time_per_call(functools.partial(run_loop, s, stepper), min_ns=0).scaled(1.0 / s.duration)
        rows.append({"method": name, "family": family, "parameter": parameter,
                     "time_per_simulated_s": per_second.median, "time_per_simulated": per_second.to_dict(),
                     "relative_error": error})
        tick(f"plant: {name}")
    exact_time = rows[0]["time_per_simulated_s"]
    for row in rows:
        row["time_ratio_to_exact"] = row["time_per_simulated_s"] / exact_time
    return {
        "description": "closed-loop contact run (push 1 N into a unilateral wall, release), time per simulated "
                       "second vs the largest relative trajectory error against a 40-digit mpmath reference",
        "scenario": {"m": s.m, "b": s.b, "T": s.T, "K": s.K, "B": s.B, "wall_at": s.wall_at, "delay": s.delay,
                     "push_N": s.push, "release_s": s.release_sample * s.T, "duration_s": s.duration,
                     "c": s.b * s.T / s.m},
        "methods": rows,
    }
