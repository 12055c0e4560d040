"""Scenes in space: planes, boxes and spheres, compiled once into a uniform grid (issue 22).

Positions in m in the device's Cartesian space (one coordinate per axis, 1 to 6 of them),
stiffness in N/m, damping in N s/m.  Every object is convex and solid inside; while the handle
penetrates it, at depth ``d`` (m) along the object's outward penetration normal ``n`` (unit),
the object pushes the handle out with ``(K d + B dd/dt) n``, ``dd/dt = -n . v`` -- so, in the
analysis' convention (:mod:`haptic_bus.control.scene`: the handle feels ``-u``), its wall force
is ``u = -(K d - B n . v) n`` (N).  Unilateral: nothing outside the object; overlapping objects
add.  Linearised at a contact, a plane is the coupled gate's wall ``K n n^T``, ``B n n^T``.

* :class:`Plane`: a point and an outward normal; solid where ``(x - point) . n < 0``;
  ``d = -(x - point) . n``.
* :class:`Box`: axis-aligned, ``center`` and ``half`` sizes; inside, the nearest face decides:
  ``d`` its distance, ``n`` its outward normal (ties: the lowest axis).
* :class:`Sphere`: ``center`` and ``radius``; ``d = radius - |x - center|``, ``n`` radial (at
  the very center: the first axis).

**Compiled once** (:func:`compile_space_scene`): the bounding box of every box and sphere is
covered by a uniform grid (cells about the median object's size, at most ``MAX_CELLS``); every
cell keeps the indices of the objects whose solid region meets it (a plane: where its half-space
meets the cell, tested once per cell).  A cycle then costs one cell lookup and an exact test of
the few objects listed there, whatever the number of objects; outside the grid only planes can
act and all of them are tested.  (A k-d tree, ``scipy.spatial.cKDTree``, answers one
``query_ball_point`` in tens of microseconds here; the grid lookup is a few arithmetic
operations in Python.)
"""

from __future__ import annotations

import dataclasses
import math
import operator
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.control.scene import validate_wall
from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range

POSITION_RANGE = (-1e6, 1e6)  # m, as the 1-D scene
SIZE_RANGE = (1e-9, 1e6)  # m: box half sizes, sphere radii
MAX_DIMENSION = 6
MAX_CELLS = 1 << 18
CELL_OVER_SIZE = 0.5  # cell edge over the median object's largest extent


def _point(field: str, value: ArrayLike, context: str) -> tuple[float, ...]:
    values = np.atleast_1d(np.asarray(value, dtype=object))
    if values.ndim != 1 or not 1 <= values.size <= MAX_DIMENSION:
        raise ParameterError(field, value, f"1 to {MAX_DIMENSION} coordinates, one per axis", context)
    return tuple(real_in_range(field, v, *POSITION_RANGE, unit="m", context=context) for v in values)


@dataclass(frozen=True)
class Plane:
    """A half-space: solid where ``(x - point) . normal < 0`` (``normal`` outward, normalised)."""

    name: str
    point: tuple[float, ...]
    normal: tuple[float, ...]
    stiffness: float
    damping: float
    _level: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        context = f"plane {self.name!r}"
        point = _point("point", self.point, context)
        normal = np.array(_point("normal", self.normal, context))
        length = math.hypot(*normal)
        if len(normal) != len(point) or length == 0.0:
            raise ParameterError("normal", self.normal, f"a nonzero vector of {len(point)} components", context)
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", tuple(float(c) for c in normal / length))
        object.__setattr__(self, "_level", math.fsum(p * n for p, n in zip(self.point, self.normal)))  # point . normal
        validate_wall(self, "plane")

    @property
    def dimension(self) -> int:
        """Number of coordinates."""
        return len(self.point)

    def bounds(self) -> None:
        """Unbounded."""
        return None

    def penetration(self, x: Sequence[float]) -> tuple[float, tuple[float, ...]] | None:
        """``(depth m, outward normal)`` at ``x`` inside, else None."""
        depth = self._level - sum(map(operator.mul, x, self.normal))
        return (depth, self.normal) if depth > 0.0 else None

    def meets(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """Whether the solid meets each axis-aligned cell ``[low, high]`` (rows)."""
        n = np.array(self.normal)
        corner = np.where(n > 0, low, high)  # the cell's point deepest in the solid
        return (corner - np.array(self.point)) @ n < 0.0


@dataclass(frozen=True)
class Box:
    """An axis-aligned box: ``center`` (m) and ``half`` sizes (m, > 0)."""

    name: str
    center: tuple[float, ...]
    half: tuple[float, ...]
    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        context = f"box {self.name!r}"
        center = _point("center", self.center, context)
        half = np.atleast_1d(np.asarray(self.half, dtype=object))
        if half.shape != (len(center),):
            raise ParameterError("half", self.half, f"{len(center)} half sizes, one per axis", context)
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "half", tuple(real_in_range("half", h, *SIZE_RANGE, unit="m", context=context) for h in half))
        validate_wall(self, "box")

    @property
    def dimension(self) -> int:
        """Number of coordinates."""
        return len(self.center)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)`` corners (m)."""
        c, h = np.array(self.center), np.array(self.half)
        return c - h, c + h

    def penetration(self, x: Sequence[float]) -> tuple[float, tuple[float, ...]] | None:
        """``(depth m, outward normal of the nearest face)`` at ``x`` inside, else None."""
        depth, face, side = math.inf, 0, 1.0
        for i, (xi, ci, hi) in enumerate(zip(x, self.center, self.half)):
            offset = xi - ci
            gap = hi - abs(offset)
            if gap <= 0.0:
                return None
            if gap < depth:
                depth, face, side = gap, i, (1.0 if offset >= 0.0 else -1.0)
        normal = [0.0] * len(self.center)
        normal[face] = side
        return depth, tuple(normal)

    def face_normals(self) -> list[tuple[float, ...]]:
        """One outward normal per pair of faces (``n`` and ``-n`` are one wall ``K n n^T``)."""
        return [tuple(1.0 if j == i else 0.0 for j in range(self.dimension)) for i in range(self.dimension)]


@dataclass(frozen=True)
class Sphere:
    """A ball: ``center`` (m) and ``radius`` (m, > 0)."""

    name: str
    center: tuple[float, ...]
    radius: float
    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        context = f"sphere {self.name!r}"
        object.__setattr__(self, "center", _point("center", self.center, context))
        object.__setattr__(self, "radius", real_in_range("radius", self.radius, *SIZE_RANGE, unit="m", context=context))
        validate_wall(self, "sphere")

    @property
    def dimension(self) -> int:
        """Number of coordinates."""
        return len(self.center)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)`` corners (m) of the bounding box."""
        c = np.array(self.center)
        return c - self.radius, c + self.radius

    def penetration(self, x: Sequence[float]) -> tuple[float, tuple[float, ...]] | None:
        """``(depth m, radial outward normal)`` at ``x`` inside, else None."""
        distance = math.dist(x, self.center)
        if distance >= self.radius:
            return None
        if distance == 0.0:
            return self.radius, tuple(1.0 if i == 0 else 0.0 for i in range(len(self.center)))
        return self.radius - distance, tuple((xi - ci) / distance for xi, ci in zip(x, self.center))


SpaceObject = Plane | Box | Sphere


@dataclass(frozen=True)
class Grid:
    """Cells of edge ``cell`` (m) from ``origin`` (m), ``counts`` per axis; ``members[k]`` the objects
    that can act in cell ``k`` (row-major, last axis fastest)."""

    origin: tuple[float, ...]
    cell: float
    counts: tuple[int, ...]
    members: tuple[tuple[int, ...], ...]

    def index(self, x: Sequence[float]) -> int:
        """The cell holding ``x``, or -1 outside the grid."""
        k = 0
        inverse = 1.0 / self.cell
        for xi, oi, ni in zip(x, self.origin, self.counts):
            i = math.floor((xi - oi) * inverse)
            if not 0 <= i < ni:
                return -1
            k = k * ni + i
        return k


class SpaceScene:
    """A compiled scene in space (module docstring).  ``force(x, v)`` is the per-cycle call."""

    def __init__(self, objects: tuple[SpaceObject, ...], grid: Grid | None, planes: tuple[int, ...]) -> None:
        self.objects = objects
        self.dimension = objects[0].dimension if objects else 0
        self.grid = grid
        self.planes = planes  # tested outside the grid
        self._walls = tuple((obj.stiffness, obj.damping) for obj in objects)

    def candidates(self, x: Sequence[float]) -> tuple[int, ...]:
        """Indices of the objects that can act at ``x``: its cell's, or every plane outside the grid."""
        grid = self.grid
        if grid is None:
            return self.planes
        k = grid.index(x)
        return self.planes if k < 0 else grid.members[k]

    def force(self, x: ArrayLike, v: ArrayLike) -> np.ndarray:
        """The wall force ``u`` (N, one entry per axis; the handle feels ``-u``) at ``x`` m moving at ``v`` m/s
        (the controller's lists of floats are read as they are, without two arrays made a cycle)."""
        xs = x if type(x) is list else np.asarray(x, dtype=float).tolist()
        vs = v if type(v) is list else np.asarray(v, dtype=float).tolist()
        return np.array(self.force_floats(xs, vs))

    def force_floats(self, x: Sequence[float], v: Sequence[float]) -> list[float]:
        """:meth:`force` for ``x`` (m) and ``v`` (m/s) given as floats, one per axis, as a list of floats: what
        a controller of several axes asks every cycle, with no array made and taken apart again."""
        u = [0.0] * len(x)
        objects, walls = self.objects, self._walls
        for index in self.candidates(x):
            hit = objects[index].penetration(x)
            if hit is None:
                continue
            depth, n = hit
            K, B = walls[index]
            push = K * depth - B * sum(map(operator.mul, v, n))
            for i, ni in enumerate(n):
                u[i] -= push * ni
        return u

    def contacts(self, x: ArrayLike) -> tuple[str, ...]:
        """Names of the objects the handle penetrates at ``x`` (m)."""
        xs = np.asarray(x, dtype=float).tolist()
        return tuple(self.objects[i].name for i in self.candidates(xs) if self.objects[i].penetration(xs) is not None)

    def touching(self, x: ArrayLike) -> tuple[str, ...]:
        """The names of the objects whose spring acts on the handle at ``x`` (m): penetrated, ``K > 0``."""
        objects = self.by_name()
        return tuple(name for name in self.contacts(x) if objects[name].stiffness > 0)

    def stored_energy(self, x: ArrayLike) -> float:
        """The energy (J) the springs acting at ``x`` (m) hold: ``sum K d^2 / 2``."""
        xs = np.asarray(x, dtype=float).tolist()
        hits = [(self.objects[i].stiffness, self.objects[i].penetration(xs)) for i in self.candidates(xs)]
        return math.fsum(0.5 * K * hit[0] ** 2 for K, hit in hits if hit is not None)

    def by_name(self) -> dict[str, SpaceObject]:
        """The scene's objects by name."""
        return {obj.name: obj for obj in self.objects}

    def with_walls(self, changes: Mapping[str, tuple[float, float]]) -> SpaceScene:
        """The same objects, those named in ``changes`` with its ``(K, B)`` (N/m, N s/m), compiled;
        ParameterError for a name the scene does not have."""
        unknown = sorted(set(changes) - {obj.name for obj in self.objects})
        if unknown:
            raise ParameterError("object", unknown[0], f"one of {sorted(obj.name for obj in self.objects)}", "scene")
        return compile_space_scene(
            dataclasses.replace(obj, stiffness=changes[obj.name][0], damping=changes[obj.name][1])
            if obj.name in changes else obj for obj in self.objects)

    def scaled(self, factor: float) -> SpaceScene:
        """The same objects with every ``K`` and ``B`` times ``factor`` (dimensionless, >= 0)."""
        return self.with_walls({obj.name: (factor * obj.stiffness, factor * obj.damping) for obj in self.objects})

    def object_dicts(self) -> list[dict[str, Any]]:
        """Every object as its profile table (:func:`space_object_to_dict`)."""
        return [space_object_to_dict(obj) for obj in self.objects]


def space_object_to_dict(obj: SpaceObject) -> dict[str, Any]:
    """An object in space as its profile table: ``kind`` ("plane", "box", "sphere"), ``name``, its
    position fields (m, as lists), K (N/m), B (N s/m)."""
    fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.init}
    return {"kind": type(obj).__name__.lower()} | {k: list(v) if isinstance(v, tuple) else v for k, v in fields.items()}


def _cell_size(finite: list[tuple[np.ndarray, np.ndarray]], low: np.ndarray, high: np.ndarray) -> float:
    """The median object's largest extent, enlarged until the grid has at most ``MAX_CELLS`` cells."""
    cell = CELL_OVER_SIZE * float(np.median([np.max(h - lo) for lo, h in finite]))
    span = np.maximum(high - low, cell)
    while np.prod(np.ceil(span / cell)) > MAX_CELLS:
        cell *= 1.25
    return cell


def _covered_cells(owners: np.ndarray, lows: np.ndarray, highs: np.ndarray, origin: np.ndarray, cell: float,
                   counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every (object, cell) pair whose bounding box ``[lows, highs]`` meets the cell: two flat arrays, vectorised."""
    first = np.clip(np.floor((lows - origin) / cell).astype(int), 0, counts - 1)
    extent = np.clip(np.floor((highs - origin) / cell).astype(int), 0, counts - 1) - first + 1
    per_object = np.prod(extent, axis=1)
    owner = np.repeat(np.arange(len(owners)), per_object)
    local = np.arange(int(per_object.sum())) - np.repeat(np.cumsum(per_object) - per_object, per_object)
    index = np.zeros(local.size, dtype=int)
    stride = 1
    for axis in reversed(range(counts.size)):
        coordinate = first[owner, axis] + local % extent[owner, axis]
        local //= extent[owner, axis]
        index += coordinate * stride
        stride *= int(counts[axis])
    return owners[owner], index


def compile_space_scene(objects: Iterable[SpaceObject]) -> SpaceScene:
    """Index ``objects`` in a uniform grid once (module docstring); names unique, one dimension for all."""
    objects = tuple(objects)
    duplicates = sorted(name for name, count in Counter(obj.name for obj in objects).items() if count > 1)
    if duplicates:
        raise ParameterError("name", duplicates[0], "a name used by one scene object only", "scene")
    dimensions = {obj.dimension for obj in objects}
    if len(dimensions) > 1:
        raise ParameterError("dimension", sorted(dimensions), "one number of coordinates for every object", "scene")
    planes = tuple(i for i, obj in enumerate(objects) if isinstance(obj, Plane))
    finite = [(i, obj.bounds()) for i, obj in enumerate(objects) if not isinstance(obj, Plane)]
    if not finite:
        return SpaceScene(objects, None, planes)
    low = np.min([b[0] for _, b in finite], axis=0)
    high = np.max([b[1] for _, b in finite], axis=0)
    cell = _cell_size([b for _, b in finite], low, high)
    counts = np.maximum(np.ceil((high - low) / cell).astype(int), 1)
    total = int(np.prod(counts))
    owners, cells = _covered_cells(np.array([i for i, _ in finite]), np.array([b[0] for _, b in finite]),
                                   np.array([b[1] for _, b in finite]), low, cell, counts)
    corners = np.stack(np.unravel_index(np.arange(total), tuple(counts)), axis=1) * cell + low if planes else low[None, :]
    for i in planes:
        plane = objects[i]
        assert isinstance(plane, Plane)
        met = np.flatnonzero(plane.meets(corners, corners + cell))
        owners, cells = np.append(owners, np.full(met.size, i)), np.append(cells, met)
    order = np.lexsort((owners, cells))
    members: list[tuple[int, ...]] = [()] * total
    bounds = np.searchsorted(cells[order], np.arange(total + 1))
    sorted_owners = owners[order].tolist()
    for k in np.flatnonzero(np.diff(bounds)):
        members[k] = tuple(sorted_owners[bounds[k] : bounds[k + 1]])
    grid = Grid(tuple(float(c) for c in low), cell, tuple(int(c) for c in counts), tuple(members))
    return SpaceScene(objects, grid, planes)
