"""Benchmark 9: a scene in space against the number of objects, beside the 1-D scene (issue 22).

Per call of ``force(x, v)`` (the per-cycle work of a scene), seconds, for 1..10 000 objects (the smoke
run: benchmark 3's 1, 100 and 1 000):

* **1-D**: :class:`haptic_bus.control.scene.CompiledScene` of benchmark 3's scenes (one wall
  ahead plus ``N - 1`` detents over 20 mm), the handle swept over them;
* **space**: :class:`haptic_bus.control.space_scene.SpaceScene` in 3-D: a floor plane plus
  ``N - 1`` spheres and boxes (alternating, seeded positions in a 20 mm cube, sizes 0.4 of their
  spacing), the handle swept along a helix through the cube and the floor;
* **space, per object**: the same objects each tested every call (no grid), up to 1 000 (100 in
  the smoke run).

Each figure is the median over a 257-point sweep of :func:`~haptic_bus.bench.timing.time_per_call`
(5 repeats); the ratio to one object is the figure over the same kind's one-object figure.
The compiled and per-object space scenes give the same force at every sweep point (checked
before timing); compile time, grid cells, and the objects tested and penetrated per call
(mean over the sweep) are reported.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from haptic_bus.bench.scene_cost import SIZES, SMOKE_SIZES, scene_objects
from haptic_bus.bench.size import Size
from haptic_bus.bench.timing import time_per_call
from haptic_bus.control.scene import compile_scene
from haptic_bus.control.space_scene import Box, Plane, SpaceObject, SpaceScene, Sphere, compile_space_scene

SPAN = 0.02  # m: the cube the objects fill
STIFFNESS, DAMPING = 1500.0, 10.0
NAIVE_UP_TO = 1_000
SWEEP = 257


def space_objects(n: int, seed: int = 22) -> list[SpaceObject]:
    """A floor plane at z = 0 and ``n - 1`` spheres and boxes in the cube ``[0, SPAN]^3`` (SI units)."""
    objects: list[SpaceObject] = [Plane("floor", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), STIFFNESS, DAMPING)]
    if n == 1:
        return objects
    rng = np.random.default_rng(seed)
    spacing = SPAN / max(round((n - 1) ** (1 / 3)), 1)
    size = 0.4 * spacing
    for i, center in enumerate(rng.uniform(0.0, SPAN, (n - 1, 3))):
        point = tuple(float(c) for c in center)
        if i % 2:
            objects.append(Box(f"box-{i}", point, (size, size, size), STIFFNESS, DAMPING))
        else:
            objects.append(Sphere(f"sphere-{i}", point, size, STIFFNESS, DAMPING))
    return objects


def sweep_points() -> np.ndarray:
    """``SWEEP`` positions (m) along a helix through the cube, dipping 1 mm into the floor."""
    s = np.linspace(0.0, 1.0, SWEEP)
    radius = 0.4 * SPAN
    return np.stack([0.5 * SPAN + radius * np.cos(6 * math.pi * s), 0.5 * SPAN + radius * np.sin(6 * math.pi * s),
                     -0.001 + (SPAN + 0.002) * s], axis=1)


class PerObject:
    """The objects of a compiled space scene, every one tested at every call (no grid)."""

    def __init__(self, scene: SpaceScene) -> None:
        self.scene = SpaceScene(scene.objects, None, tuple(range(len(scene.objects))))

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The summed wall force (N) of every object the handle penetrates."""
        return self.scene.force(x, v)


def _sweep_time(force: Callable[[Any, Any], Any], points: list[Any], velocity: Any, min_ns: int) -> dict[str, float | int]:
    def sweep() -> None:
        for x in points:
            force(x, velocity)

    return time_per_call(sweep, min_ns=min_ns).scaled(1.0 / len(points)).to_dict()


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 9; returns its section of ``bench.json``."""
    min_ns = size.pick(100_000, 2_000_000, 2_000_000)  # ns each timing runs at least
    points = list(sweep_points())
    velocity = np.array([0.01, -0.02, -0.01])
    xs = [float(x) for x in np.linspace(-0.021, 0.003, SWEEP)]
    rows: list[dict[str, Any]] = []
    sizes = size.pick(SMOKE_SIZES, SIZES, SIZES)  # smoke: benchmark 3's sizes; compiling 10 000 objects and
    # sweeping them is 1 s of the smoke's CPU, and 1 000 objects already build the grid and cull by it
    for n in sizes:
        started = time.perf_counter()
        space = compile_space_scene(space_objects(n))
        compile_s = time.perf_counter() - started
        line = compile_scene(scene_objects(n))
        row: dict[str, Any] = {"objects": n, "compile_space_s": compile_s,
                               "grid_cells": 0 if space.grid is None else len(space.grid.members),
                               "candidates_per_call": float(np.mean([len(space.candidates(x.tolist())) for x in points])),
                               "contacts_per_call": float(np.mean([len(space.contacts(x)) for x in points])),
                               "space_force": _sweep_time(space.force, points, velocity, min_ns),
                               "line_force": _sweep_time(line.force, xs, 0.01, min_ns)}
        if n <= size.pick(NAIVE_UP_TO // 10, NAIVE_UP_TO, NAIVE_UP_TO):
            naive = PerObject(space)
            for x in points:
                if not np.allclose(space.force(x, velocity), naive.force(x, velocity), rtol=1e-12, atol=1e-12):
                    raise AssertionError(f"compiled and per-object space scenes disagree at x = {x}")
            row["per_object_force"] = _sweep_time(naive.force, points, velocity, size.pick(min_ns, 1_000_000, 1_000_000))
        rows.append(row)
        tick(f"space scene: {n} objects")
    for row in rows:
        row["space_ratio_to_one_object"] = row["space_force"]["median"] / rows[0]["space_force"]["median"]
        row["line_ratio_to_one_object"] = row["line_force"]["median"] / rows[0]["line_force"]["median"]
        if "per_object_force" in row:
            row["per_object_over_compiled"] = row["per_object_force"]["median"] / row["space_force"]["median"]
    return {
        "description": "force(x, v) per call vs number of objects: the 3-D scene (floor plane + spheres and boxes, "
                       "uniform grid) beside the 1-D compiled scene and the 3-D objects tested one by one",
        "rows": rows,
        "note": "one call = one cycle's scene evaluation; the 1-D figures are force() alone, not benchmark 3's whole cycle",
        "size": size.name,
        "sizes": list(sizes),
    }
