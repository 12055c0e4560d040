"""Scenes: the virtual objects the handle can touch, compiled once into a piecewise-affine law.

One axis, SI units: positions in m, stiffness in N/m, damping in N s/m.  Every object acts
on an interval of handle positions (its *support*) with a linear spring-damper law there; the
wall force that opposes the handle (the seed's ``u``, N) is

    u(x, v) = sum over objects whose support contains x of  K_i (x - anchor_i) + B_i v.

:func:`compile_scene` sweeps the support end points once and stores, for every interval
between consecutive end points, the summed ``(K, K * anchor, B)``.  A cycle then costs one
``bisect`` (C code, ``log2 N`` comparisons) and one affine evaluation, whatever the number of
objects: a 1 000-object scene costs what a one-object scene costs.  Overlapping objects add,
and the summed ``(K, B)`` of every interval is what the passivity gate judges.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
import re
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from haptic_bus.analysis.loop import DAMPING_RANGE, STIFFNESS_RANGE
from haptic_bus.control import protocols
from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range, some_names

_POSITION_RANGE = (-1e6, 1e6)  # m


def validate_wall(obj: protocols.SceneObject, kind: str) -> None:
    """Set ``obj``'s (a frozen dataclass') stiffness (N/m) and damping (N s/m) to validated floats, else
    ParameterError naming ``kind`` and its name."""
    context = f"{kind} {obj.name!r}"
    object.__setattr__(obj, "stiffness", real_in_range("stiffness", obj.stiffness, *STIFFNESS_RANGE, unit="N/m",
                                                        context=context))
    object.__setattr__(obj, "damping", real_in_range("damping", obj.damping, *DAMPING_RANGE, unit="N s/m", context=context))


def _position(field: str, value: float, context: str) -> float:
    return real_in_range(field, value, *_POSITION_RANGE, unit="m", context=context)


@dataclass(frozen=True)
class Wall:
    """A unilateral wall at ``position``: solid on the side ``normal`` points away from.

    ``normal = -1``: solid for ``x > position`` (the operator pushes in +x into it);
    ``normal = +1``: solid for ``x < position``.  Acts only while penetrating, with
    ``u = K (x - position) + B v``.
    """

    name: str
    position: float
    normal: int
    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        if isinstance(self.normal, bool) or self.normal not in (-1, 1):
            raise ParameterError("normal", self.normal, "-1 (solid above position) or +1 (solid below)", f"wall {self.name!r}")
        object.__setattr__(self, "normal", int(self.normal))
        validate_wall(self, "wall")
        object.__setattr__(self, "position", _position("position", self.position, f"wall {self.name!r}"))

    def pieces(self) -> list[tuple[float, float, float, float, float]]:
        """(start m, end m, K N/m, anchor m, B N s/m) of each support interval."""
        if self.normal == -1:
            return [(self.position, math.inf, self.stiffness, self.position, self.damping)]
        return [(-math.inf, self.position, self.stiffness, self.position, self.damping)]


@dataclass(frozen=True)
class Slot:
    """A box the handle is held inside: walls at ``low`` and ``high`` facing each other (m)."""

    name: str
    low: float
    high: float
    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        validate_wall(self, "slot")
        low = _position("low", self.low, f"slot {self.name!r}")
        high = _position("high", self.high, f"slot {self.name!r}")
        if not high > low:
            raise ParameterError("high", self.high, f"greater than low = {low:g} m", f"slot {self.name!r}")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    def pieces(self) -> list[tuple[float, float, float, float, float]]:
        K, B = self.stiffness, self.damping
        return [(-math.inf, self.low, K, self.low, B), (self.high, math.inf, K, self.high, B)]


@dataclass(frozen=True)
class Detent:
    """A bilateral spring-damper pulling to ``center`` within ``reach`` m of it (a detent)."""

    name: str
    center: float
    reach: float
    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        validate_wall(self, "detent")
        object.__setattr__(self, "center", _position("center", self.center, f"detent {self.name!r}"))
        object.__setattr__(self, "reach", real_in_range("reach", self.reach, 0.0, 1e6, low_inclusive=False, unit="m",
                                                        context=f"detent {self.name!r}"))

    def pieces(self) -> list[tuple[float, float, float, float, float]]:
        return [(self.center - self.reach, self.center + self.reach, self.stiffness, self.center, self.damping)]


SceneObject = Wall | Slot | Detent
OBJECT_KINDS: dict[str, type[SceneObject]] = {"wall": Wall, "slot": Slot, "detent": Detent}
ObjectT = TypeVar("ObjectT", bound=SceneObject)


def with_wall_law(obj: ObjectT, stiffness: float, damping: float) -> ObjectT:
    """``obj`` with its stiffness (N/m) and damping (N s/m) replaced, validated again."""
    return dataclasses.replace(obj, stiffness=stiffness, damping=damping)


def object_to_dict(obj: SceneObject) -> dict[str, Any]:
    """A scene object as its profile's TOML table: ``kind`` plus every field (m, N/m, N s/m)."""
    kind = next(name for name, cls in OBJECT_KINDS.items() if isinstance(obj, cls))
    return {"kind": kind, **{k: getattr(obj, k) for k in obj.__dataclass_fields__}}


def object_from_dict(table: dict[str, Any]) -> SceneObject:
    """The object :func:`object_to_dict` wrote (validated as any object is)."""
    fields = dict(table)
    kind = fields.pop("kind", None)
    if kind not in OBJECT_KINDS:
        raise ParameterError("kind", kind, " or ".join(map(repr, OBJECT_KINDS)), "scene object")
    return OBJECT_KINDS[kind](**fields)


@dataclass(frozen=True)
class CompiledScene:
    """The scene as a piecewise-affine law: ``breaks`` (m, sorted) split the axis into
    ``len(breaks) + 1`` intervals; interval ``i`` has ``u = k[i] x - k_anchor[i] + damping[i] v``.
    """

    objects: tuple[SceneObject, ...]
    breaks: tuple[float, ...]
    stiffness: tuple[float, ...]
    stiffness_anchor: tuple[float, ...]
    damping: tuple[float, ...]
    contributors: tuple[tuple[str, ...], ...]

    def force(self, x: float, v: float) -> float:
        """The wall force ``u`` (N, opposing the handle) at position ``x`` m and velocity ``v`` m/s."""
        i = bisect.bisect_right(self.breaks, x)
        return self.stiffness[i] * x - self.stiffness_anchor[i] + self.damping[i] * v

    def force_floats(self, x: Sequence[float], v: Sequence[float]) -> list[float]:
        """:meth:`force` of the one axis in the scene protocol's lists: ``[u]`` (N) for ``[x]`` (m), ``[v]`` (m/s)."""
        return [self.force(x[0], v[0])]

    def contacts(self) -> dict[tuple[float, float], tuple[str, ...]]:
        """Every distinct summed ``(K, B)`` that can act on the handle at once, with the names
        of every object that makes it up somewhere (overlapping objects add)."""
        found: dict[tuple[float, float], set[str]] = {}
        for k, b, names in zip(self.stiffness, self.damping, self.contributors):
            if k > 0 or b > 0:
                found.setdefault((k, b), set()).update(names)
        return {wall: tuple(sorted(names, key=_natural)) for wall, names in found.items()}

    def by_name(self) -> dict[str, SceneObject]:
        """The scene's objects by name."""
        return {obj.name: obj for obj in self.objects}

    def contact(self, x: float) -> tuple[tuple[str, ...], float, float]:
        """At position ``x`` (m): the objects acting, the force they exert at rest (N, opposing the
        handle) and their summed stiffness (N/m); a handle at rest inside a wall feels that force."""
        i = bisect.bisect_right(self.breaks, x)
        return self.contributors[i], self.stiffness[i] * x - self.stiffness_anchor[i], self.stiffness[i]

    def touching(self, x: float) -> tuple[str, ...]:
        """The names of the objects whose spring acts on the handle at ``x`` (m): penetrated, ``K > 0``."""
        objects = self.by_name()
        return tuple(name for name in self.contact(x)[0] if objects[name].stiffness > 0)

    def stored_energy(self, x: float) -> float:
        """The energy (J) the springs acting at ``x`` (m) hold: ``sum K (x - anchor)^2 / 2``."""
        return math.fsum(0.5 * K * (x - anchor) ** 2
                         for obj in self.objects
                         for start, end, K, anchor, _ in obj.pieces() if start <= x < end)

    def with_walls(self, changes: Mapping[str, tuple[float, float]]) -> CompiledScene:
        """The same objects, those named in ``changes`` with its ``(K, B)`` (N/m, N s/m), compiled;
        ParameterError for a name the scene does not have."""
        unknown = sorted(set(changes) - {obj.name for obj in self.objects})
        if unknown:
            raise ParameterError("object", unknown[0], f"one of {some_names(sorted(obj.name for obj in self.objects), ', ')}",
                                 "scene")
        return compile_scene(with_wall_law(obj, *changes[obj.name]) if obj.name in changes else obj
                             for obj in self.objects)

    def object_dicts(self) -> list[dict[str, Any]]:
        """Every object as its profile's TOML table (:func:`object_to_dict`)."""
        return [object_to_dict(obj) for obj in self.objects]

    def scaled(self, factor: float) -> CompiledScene:
        """The same objects with every ``K`` and ``B`` times ``factor`` (dimensionless, >= 0)."""
        return compile_scene(with_wall_law(obj, factor * obj.stiffness, factor * obj.damping) for obj in self.objects)


_ULP_SCALE = 1 << 1074  # the smallest float's reciprocal: every finite float is an integer number of 2**-1074


def _exact(value: float) -> int:
    """A finite float as the integer number of 2**-1074 it is (exact)."""
    numerator, denominator = value.as_integer_ratio()
    return numerator * (_ULP_SCALE // denominator)


def compile_scene(objects: Iterable[SceneObject]) -> CompiledScene:
    """Sweep the objects' support intervals once into a :class:`CompiledScene`.

    Each interval's sums are the exact sums of the pieces active there, rounded once (the value ``math.fsum``
    gives): an interval where nothing acts has exactly zero force and no round-off carries from one interval
    to the next.  The exact sums are kept running (:func:`_exact`: a float is an integer number of 2**-1074,
    so adding and taking away loses nothing) and rounded with one division, so the sweep costs the pieces
    that enter and leave at each break, not every piece active there (an fsum per interval over 3 000
    overlapping walls: 9 million terms and 2.3 s, twice per profile check).
    """
    objects = tuple(objects)
    duplicates = sorted(name for name, count in Counter(obj.name for obj in objects).items() if count > 1)
    if duplicates:
        raise ParameterError("name", duplicates[0], "a name used by one scene object only", "scene")
    pieces = [piece for obj in objects for piece in obj.pieces()]
    owners = [obj.name for obj in objects for _ in obj.pieces()]
    starts: dict[float, list[int]] = {}
    ends: dict[float, list[int]] = {}
    first: list[int] = []
    for i, (start, end, _, _, _) in enumerate(pieces):
        if start == -math.inf:
            first.append(i)
        else:
            starts.setdefault(start, []).append(i)
        if end != math.inf:
            ends.setdefault(end, []).append(i)
    breaks = sorted(set(starts) | set(ends))
    ks: list[float] = []
    kas: list[float] = []
    bs: list[float] = []
    who: list[tuple[str, ...]] = []
    values = [(K, K * anchor, B) for _, _, K, anchor, B in pieces]
    active: set[int] = set()
    sums = [0, 0, 0]  # K, K * anchor, B of the active pieces, exact (in 2**-1074)
    acting: Counter[str] = Counter()  # the active pieces' owners
    names: list[str] = []  # the owners acting, sorted

    def change(i: int, sign: int) -> None:
        for j, value in enumerate(values[i]):
            sums[j] += sign * _exact(value)
        owner = owners[i]
        acting[owner] += sign
        if sign > 0 and acting[owner] == 1:
            bisect.insort(names, owner)
        elif sign < 0 and acting[owner] == 0:
            del names[bisect.bisect_left(names, owner)]

    def close_interval() -> None:
        who.append(tuple(names))
        for j, out in enumerate((ks, kas, bs)):
            out.append(sums[j] / _ULP_SCALE)

    for i in first:
        active.add(i)
        change(i, 1)
    close_interval()
    for at in breaks:
        for i in ends.get(at, ()):
            if i in active:
                active.remove(i)
                change(i, -1)
        for i in starts.get(at, ()):
            if i not in active:
                active.add(i)
                change(i, 1)
        close_interval()
    return CompiledScene(objects, tuple(breaks), tuple(ks), tuple(kas), tuple(bs), tuple(who))


def _natural(name: str) -> tuple[tuple[int, int | str], ...]:
    """A name's sort key with its runs of digits as numbers: w2 before w10, as a profile numbers its walls (a
    refusal naming three of 1 000 nested walls said 'w0+w1+w10 and 277 more'); otherwise alphabetical."""
    return tuple((0, int(part)) if part.isdigit() else (1, part) for part in re.split(r"(\d+)", name) if part)

