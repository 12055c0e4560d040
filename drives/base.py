"""The one small interface every fieldbus drive implements, and the drive-unit scaling.

A controller needs exactly this from a drive: connect, enable in a mode, read the cyclic
inputs of a cycle, write the cyclic outputs of that cycle, disable, fault reset, close.
Cyclic values travel in the drive's own integer units (0x606C velocity units, 0x6064
increments, 0x6071 per mille of rated torque); :class:`DriveScaling` converts them to SI
once, at the drive edge.  A loop takes its cycles from :meth:`Drive.cyclic` (a
:class:`DriveCycle`, bound once), and every target torque passes the drive's
:class:`TorqueClamp`, the one place one is saturated.
"""

from __future__ import annotations

import abc
import contextlib
import functools
import math
import numbers
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from drives.cia402 import ObjectSpec, OperationMode
from drives.errors import DriveError, ParameterError
from drives.ranges import real_in_range


@dataclass(frozen=True, slots=True)
class CyclicInputs:
    """What the drive reports each cycle, in its own integer units.

    ``position`` is None when the cyclic mapping does not carry 0x6064.  ``age``: how many samples
    older than its cycle the input is (0: this cycle's; a master that hands out the last input
    again when this cycle's did not arrive counts up).  ``sampled_by_ns``: ``time.perf_counter_ns()``
    by which the drive had sampled them (right after the SYNC left, or when the Modbus answer
    arrived): an upper bound of the sampling instant on this process's clock; 0 when unknown.
    """

    statusword: int
    velocity: int
    position: int | None = None
    age: int = 0
    sampled_by_ns: int = 0


@dataclass(frozen=True)
class DriveScaling:
    """Conversion between drive units and SI at the handle.

    ``velocity_per_count``: handle velocity in m/s of one 0x606C unit.
    ``position_per_count``: handle position in m of one 0x6064 increment.
    ``rated_torque``: 0x6076 in N m.  ``force_per_torque``: handle force in N per N m of
    motor torque (the transmission, 1/m).  ``max_torque_permille``: 0x6072.
    """

    velocity_per_count: float
    position_per_count: float
    rated_torque: float
    force_per_torque: float
    max_torque_permille: int = 1000

    def __post_init__(self) -> None:
        for name in ("velocity_per_count", "position_per_count", "rated_torque", "force_per_torque"):
            real_in_range(name, getattr(self, name), 0.0, math.inf, low_inclusive=False, context="drive scaling")
        permille = self.max_torque_permille
        if isinstance(permille, bool) or not isinstance(permille, int) or not 1 <= permille <= 0xFFFF:
            raise ParameterError("max_torque_permille", permille, "an integer in [1, 65535] (0x6072)", "drive scaling")

    @functools.cached_property
    def newton_per_permille(self) -> float:
        """Handle force in N of one per-mille unit of 0x6071 (the scaling is frozen: computed once, read
        by :meth:`torque_permille` every cycle on every axis)."""
        return self.rated_torque * self.force_per_torque / 1000.0

    @property
    def max_force(self) -> float:
        """The handle force in N that 0x6072 allows."""
        return self.max_torque_permille * self.newton_per_permille

    def torque_permille(self, force: float) -> int:
        """The 0x6071 value (per mille, rounded) for a handle force in N; not saturated: the drive's
        :class:`TorqueClamp` is the one place a target is held within +-0x6072.  The quotient in the
        force's own type (a NumPy float32 force stays float32), rounded as a Python float: the same
        value (half to even) as rounding a NumPy scalar, 20 times faster (2.1 -> 0.1 us, every cycle)."""
        return round(float(force / self.newton_per_permille))

    def torque_limit(self, force_limit: float) -> int | None:
        """The per mille a handle force limit in N allows, rounded, for a drive's cyclic phase
        (:meth:`Drive.cyclic`); None beyond what 0x6071 carries (the drive's own 0x6072 holds)."""
        limit = force_limit / self.newton_per_permille
        return round(limit) if limit < 0x7FFF else None


SCALING_FIELDS = ("velocity_per_count", "position_per_count", "rated_torque", "force_per_torque", "max_torque_permille")
SCALING_UNITS = {"velocity_per_count": "m/s", "position_per_count": "m", "rated_torque": "N m",
                 "force_per_torque": "N/(N m)", "max_torque_permille": "per mille"}


@dataclass(frozen=True)
class ScalingReading:
    """One value of a :class:`DriveScaling` field and where it was read.

    ``source``: the object or chain of objects ("0x6076", "0x6091/0x6092/0x60A8", "0x2001:01"),
    or the caller's label ("caller", "profile [device]").  ``tolerance``: the relative rounding
    the source's integer objects allow (0: exact).  ``detail``: how the value was derived.
    """

    value: float | int
    source: str
    tolerance: float = 0.0
    detail: str = ""


@dataclass(frozen=True)
class ScalingFactor:
    """One field of the scaling in use: the reading ``used`` and the other readings that ``agreed`` with it."""

    name: str
    used: ScalingReading
    agreed: tuple[ScalingReading, ...] = ()

    def line(self) -> str:
        """``name = value unit from source (detail); agrees with ...``: one line for a log or a terminal."""
        used = self.used
        text = f"{self.name} = {used.value!r} {SCALING_UNITS.get(self.name, '')} from {used.source}"
        if used.detail:
            text += f" ({used.detail})"
        if self.agreed:
            text += "; agrees with " + ", ".join(f"{r.source} ({r.value!r})" for r in self.agreed)
        return text


@dataclass(frozen=True)
class ScalingReport:
    """Where every factor of a drive's :class:`DriveScaling` came from, after ``connect()``.

    ``factors`` in :data:`SCALING_FIELDS` order; ``notes``: why the drive could not give a factor
    (an object it lacks, a unit with no SI length), each a sentence.
    """

    factors: tuple[ScalingFactor, ...]
    notes: tuple[str, ...] = ()

    @property
    def sources(self) -> dict[str, str]:
        """Field -> the source of the value in use."""
        return {f.name: f.used.source for f in self.factors}

    def lines(self) -> list[str]:
        """One line per factor, then the notes: what a run prints."""
        return [f.line() for f in self.factors] + [f"note: {note}" for note in self.notes]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict: per field its value, unit, source, detail, tolerance and agreeing sources; the notes."""
        return {
            "factors": {
                f.name: {"value": f.used.value, "unit": SCALING_UNITS.get(f.name, ""), "source": f.used.source,
                         "detail": f.used.detail, "tolerance": f.used.tolerance,
                         "agreed": [{"source": r.source, "value": r.value} for r in f.agreed]}
                for f in self.factors
            },
            "notes": list(self.notes),
        }


class SaturationCount(Protocol):
    """Where a :class:`TorqueClamp` counts the targets it clamped (a drive's cyclic stats)."""

    saturated_outputs: int


class TorqueClamp:
    """The one place a target torque is saturated: at +-``limit`` per mille, each clamp counted
    once in ``counts.saturated_outputs``.  A drive holds one (``limit``: 0x6072, or lower while a
    caller's :meth:`Drive.cyclic` asks for less); a controller's force limit reaches the drive as
    that lower limit, so a target is clamped once, at one limit, wherever it comes from."""

    __slots__ = ("counts", "limit")

    def __init__(self, limit: int, counts: SaturationCount) -> None:
        self.limit = limit
        self.counts = counts

    @contextlib.contextmanager
    def lowered(self, limit: int | None, owner: str) -> Iterator[TorqueClamp]:
        """This clamp held at ``limit`` (per mille; None: unchanged) if that is lower, until the block
        ends; ``limit`` None or an integer >= 1, else ParameterError naming ``owner`` (the drive)."""
        own = self.limit
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, numbers.Integral) or limit < 1):
            raise ParameterError("torque_limit", limit,
                                 f"None or an integer >= 1 per mille (held to the drive's own {own}, 0x6072)", owner)
        if limit is not None:
            self.limit = min(own, int(limit))
        try:
            yield self
        finally:
            self.limit = own

    def __call__(self, torque: int) -> int:
        """``torque`` (per mille) held within +-``limit``."""
        limit = self.limit
        if torque > limit:
            self.counts.saturated_outputs += 1
            return limit
        if torque < -limit:
            self.counts.saturated_outputs += 1
            return -limit
        return torque


class DriveCycle:
    """One drive's cyclic phase, bound once when it begins (``with drive.cyclic(limit) as cycle``).

    ``read()`` starts a cycle and returns its inputs; ``saturate(torque)`` is the drive's
    :class:`TorqueClamp` (per mille, at the phase's limit, counted); ``write(torque)`` sends a
    target ``saturate`` returned (or the safe outputs while the drive is tripped).  A controller
    that lowers a target after saturating it (the passivity layer) calls the two in turn;
    :meth:`saturate_and_write` is both for one that does not.  A target is an integer (per mille of the
    rated torque, 0x6071), else :class:`~drives.errors.ParameterError` and nothing is sent;
    once the phase has ended, ``read`` and ``write`` raise :class:`~drives.errors.DriveError`.
    """

    __slots__ = ("_name", "_read", "_send", "open", "saturate")

    def __init__(self, name: str, read: Callable[[], CyclicInputs], saturate: TorqueClamp,
                 send: Callable[[int], None]) -> None:
        self._name, self._read, self.saturate, self._send = name, read, saturate, send
        self.open = True

    def _check_open(self) -> None:
        if not self.open:
            raise DriveError(self._name, "its cyclic phase has ended: read and write inside 'with drive.cyclic()'")

    def read(self) -> CyclicInputs:
        """Start a cycle: the drive's inputs of this cycle."""
        self._check_open()
        return self._read()

    def write(self, torque: int) -> None:
        """Send ``torque`` (per mille, as :meth:`saturate` returned it) with this cycle's controlword."""
        self._check_open()
        self._send(checked_torque(self._name, torque))

    def saturate_and_write(self, torque: int) -> int:
        """Saturate ``torque`` and send it; the torque sent (per mille)."""
        self._check_open()
        torque = self.saturate(checked_torque(self._name, torque))
        self._send(torque)
        return torque


def checked_torque(name: str, torque: object) -> int:
    """``torque`` as a target torque (per mille): an integer (numpy's too), else ParameterError."""
    if type(torque) is int:  # every cycle of the controllers: the one check they pay (26 ns, not 0.7 us)
        return torque
    if isinstance(torque, bool) or not isinstance(torque, numbers.Integral):
        raise ParameterError("target torque", torque, "an integer, per mille of the rated torque (0x6071)", name)
    return int(torque)


@dataclass(frozen=True, slots=True)
class AxesDriveCycle:
    """Several drives' cyclic phase on one SYNC, bound once (``with axes.cyclic(limits) as cycle``).

    The shape of a :class:`DriveCycle`, one value per axis in axis order: ``read()`` starts a cycle
    (one SYNC) and returns every axis' inputs; ``clamps`` are the axes' :class:`TorqueClamp` (per
    mille, each at its axis' limit, counted in its drive's stats); ``write(torques)`` sends targets
    :meth:`saturate` returned (or the safe outputs on every axis once any tripped).  ``one``: for one
    drive seen as axes (:class:`OneAxis`), that drive's own :class:`DriveCycle`, which a controller's
    scalar path calls directly (no tuple a cycle); None for several drives.
    """

    read: Callable[[], tuple[CyclicInputs, ...]]
    clamps: tuple[TorqueClamp, ...]
    write: Callable[[Sequence[int]], None]
    one: DriveCycle | None = None

    def saturate(self, torques: Sequence[int]) -> list[int]:
        """Every axis' ``torques`` (per mille) through its own clamp."""
        return [clamp(torque) for clamp, torque in zip(self.clamps, torques)]

    def saturate_and_write(self, torques: Sequence[int]) -> list[int]:
        """Saturate ``torques`` and send them; the torques sent (per mille)."""
        sent = self.saturate(torques)
        self.write(sent)
        return sent


class Drive(abc.ABC):
    """A servo drive reached over a fieldbus, seen from the controller.

    The cycle is ``read_inputs()`` then ``write_outputs()``: on CANopen ``read_inputs``
    produces the SYNC and waits for the drive's TPDO, on Modbus it is one read request.
    A loop of many cycles takes them from :meth:`cyclic` instead, bound once.  A subclass sets
    ``clamp`` (its :class:`TorqueClamp`) and implements :meth:`_send_torque`.
    """

    name: str
    scaling: DriveScaling
    clamp: TorqueClamp
    last_inputs: CyclicInputs | None = None  # the inputs of the last cycle it took part in (None: none yet)
    _phase_open = False  # True inside :meth:`cyclic`

    @abc.abstractmethod
    def connect(self) -> object:
        """Reach the drive and configure it (cyclic mapping, cycle period); raise DriveTimeout.
        Returns what the connection holds (a subclass says what)."""

    @abc.abstractmethod
    def enable(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """Set ``mode`` (checked against 0x6502 and 0x6061) and walk to OPERATION ENABLED."""

    @abc.abstractmethod
    def select_mode(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """Set ``mode`` ahead of the next :meth:`enable`, which then only walks the state machine."""

    @abc.abstractmethod
    def read_object(self, spec: ObjectSpec | int) -> int:
        """Read one object acyclically (SDO upload, register read) in drive units."""

    @abc.abstractmethod
    def read_inputs(self) -> CyclicInputs:
        """Start a cycle and return the drive's inputs of this cycle; raise on timeout or fault."""

    def write_outputs(self, target_torque: int) -> None:
        """Send this cycle's target torque (0x6071, per mille of rated torque, an integer), saturated by ``clamp``."""
        self._send_torque(self.clamp(checked_torque(self.name, target_torque)))

    @abc.abstractmethod
    def _send_torque(self, target_torque: int) -> None:
        """Send a saturated target torque (per mille) with this cycle's controlword."""

    @contextlib.contextmanager
    def cyclic(self, torque_limit: int | None = None) -> Iterator[DriveCycle]:
        """The cyclic phase: a :class:`DriveCycle` bound once, whose ``saturate`` holds targets within
        ``torque_limit`` (per mille; None: the drive's own, 0x6072) until the phase ends."""
        if self._phase_open:
            raise DriveError(self.name, "a cyclic phase is open already: one 'with drive.cyclic()' at a time")
        with self.clamp.lowered(torque_limit, self.name), self._phase_duties():
            cycle = self._bind_cycle()
            self._phase_open = True
            try:
                yield cycle
            finally:
                cycle.open = False
                self._phase_open = False

    def _phase_duties(self) -> contextlib.AbstractContextManager[None]:
        """What the cyclic phase takes over while it runs (CANopen: the controller's heartbeat); none here."""
        return contextlib.nullcontext()

    def _bind_cycle(self) -> DriveCycle:
        """The cycle's bound methods (a bus enters its cyclic phase here)."""
        return DriveCycle(self.name, self.read_inputs, self.clamp, self._send_torque)

    @abc.abstractmethod
    def disable(self) -> None:
        """Zero the torque and bring the drive to a safe state (SWITCH ON DISABLED)."""

    @abc.abstractmethod
    def fault_reset(self) -> None:
        """Clear a drive fault (rising edge of controlword bit 7)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the bus; the drive object is unusable afterwards."""

    def __enter__(self) -> Drive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class AxesDrive(Protocol):
    """What a controller drives: N drives on one SYNC (:class:`drives.canopen.axes.CanopenAxes`), or
    one drive as N = 1 (:class:`OneAxis`)."""

    name: str

    @property
    def drives(self) -> Sequence[Drive]:
        """Every axis' drive, in axis order (acyclic reads: 0x6064 before cycling)."""
        ...

    @property
    def scalings(self) -> tuple[DriveScaling, ...]:
        """Every axis' drive-unit scaling, in axis order."""
        ...

    def cyclic(self, torque_limits: Sequence[int | None] | None = None
               ) -> contextlib.AbstractContextManager[AxesDriveCycle]:
        """The cyclic phase of every axis (one SYNC per cycle; any axis' fault trips every axis), each
        axis' clamp held within its ``torque_limits`` entry (per mille; None: its drive's own)."""
        ...

    def disable(self) -> None:
        """Zero torque and every drive disabled."""
        ...


class OneAxis:
    """One :class:`Drive` as axes on one SYNC, N = 1: its cyclic phase in the N-shape
    (:class:`AxesDriveCycle`), carrying the drive's own :class:`DriveCycle` as ``one``."""

    def __init__(self, drive: Drive) -> None:
        self.drive = drive
        self.name = drive.name
        self.drives = (drive,)

    @property
    def scalings(self) -> tuple[DriveScaling, ...]:
        """The drive's scaling, the one axis'."""
        return (self.drive.scaling,)

    @contextlib.contextmanager
    def cyclic(self, torque_limits: Sequence[int | None] | None = None) -> Iterator[AxesDriveCycle]:
        """The drive's cyclic phase (:meth:`Drive.cyclic`, its clamp within ``torque_limits[0]`` per mille)."""
        with self.drive.cyclic(torque_limits[0] if torque_limits else None) as cycle:
            yield AxesDriveCycle(lambda: (cycle.read(),), (cycle.saturate,), lambda torques: cycle.write(torques[0]),
                                 one=cycle)

    def disable(self) -> None:
        """Torque zero, the drive disabled."""
        self.drive.disable()
