"""What a master of several CiA-402 drives does the same on every fieldbus.

:class:`AxesMaster` holds the drives, one per axis in axis order (at most :data:`MAX_AXES`), and
does what :class:`~drives.canopen.axes.CanopenAxes` (one SYNC) and
:class:`~drives.modbus.axes.ModbusAxes` (one poll) do alike: it connects every drive or none (on
any failure everything is closed again), walks their state machines together
(:func:`walk_together`: one exchange of every drive per step, the bus'
:meth:`AxesMaster._command`, so that no drive is left without its master while another walks),
trips them all when one fails (:func:`trip_together`), takes the cyclic phase's torque limits one per axis, and refuses
use before :meth:`AxesMaster.connect` or after :meth:`AxesMaster.close`.  The bus' own part --
commissioning, the cyclic phase, the trip of every axis, the goodbye -- is the subclass'.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence
from typing import Generic, Self, TypeVar

from drives.base import CyclicInputs, DriveScaling
from drives.cia402 import SAFE_CONTROLWORD, State
from drives.cia402_master import Cia402Master
from drives.errors import DriveError, ParameterError
from drives.state_walk import StateWalk

MAX_AXES = 6

DriveT = TypeVar("DriveT", bound=Cia402Master)


class AxesMaster(abc.ABC, Generic[DriveT]):
    """The drives ``drives`` of one device, one per axis, walked together (module docstring).

    A subclass sets ``name`` and ``drives`` and implements :meth:`_reach` (reach and commission
    every drive), :meth:`_command` (one state-machine step of every drive) and :meth:`close`.
    """

    name: str
    drives: tuple[DriveT, ...]
    _connected = False
    _closed = False

    @property
    def scalings(self) -> tuple[DriveScaling, ...]:
        """Every axis' drive-unit scaling (after :meth:`connect`)."""
        return tuple(drive.scaling for drive in self.drives)

    def connect(self) -> None:
        """Reach every drive (:meth:`_reach`); on any failure everything is closed again and the error raised."""
        if self._closed:
            raise DriveError(self.name, "closed; create a new one")
        if self._connected:
            return
        try:
            self._reach()
        except BaseException:
            self.close()
            raise
        self._connected = True

    @abc.abstractmethod
    def _reach(self) -> None:
        """Reach and commission every drive in turn, as the bus does it."""

    def enable(self) -> None:
        """Every drive to OPERATION ENABLED in cyclic synchronous torque mode, walked together."""
        self._require_connected()
        self._before_walk()
        enable_together(self.drives, self._command)

    def _before_walk(self) -> None:
        """What the bus does before the drives are enabled (nothing here)."""

    def disable(self) -> None:
        """Zero torque and DISABLE VOLTAGE on every drive, walked together to SWITCH ON DISABLED (or FAULT)."""
        if not self._connected:
            return
        disable_together(self.drives, self._command)

    @abc.abstractmethod
    def _command(self, words: list[int]) -> list[int]:
        """One step of every drive's state machine: each drive's controlword ``words[i]`` sent with zero
        torque, and each drive's statusword of that exchange, in axis order."""

    def _axis_limits(self, torque_limits: Sequence[int | None] | None) -> list[int | None]:
        """``torque_limits`` of a cyclic phase (per mille; None: every drive's own 0x6072) as one
        entry per axis; ParameterError for another count."""
        limits: list[int | None] = list(torque_limits) if torque_limits is not None else [None] * len(self.drives)
        self._one_per_axis("torque_limits", len(limits))
        return limits

    def _one_per_axis(self, name: str, count: int) -> None:
        """ParameterError unless ``count`` values of ``name`` are one per axis."""
        if count != len(self.drives):
            raise ParameterError(name, count, f"one per axis ({len(self.drives)})", self.name)

    @abc.abstractmethod
    def read_inputs(self) -> tuple[CyclicInputs, ...]:
        """One cycle's inputs of every axis, in axis order (outside a cyclic phase); any axis' error
        trips every axis and is raised."""

    @abc.abstractmethod
    def write_outputs(self, torques: Sequence[int]) -> None:
        """Every axis' target torque (0x6071, per mille, in axis order), each saturated by its drive's clamp."""

    @abc.abstractmethod
    def close(self) -> None:
        """Every drive's safe outputs and goodbye, the bus released; never raises for a bus that is gone."""

    def _require_connected(self) -> None:
        if self._closed:
            raise DriveError(self.name, "closed; create a new one")
        if not self._connected:
            raise DriveError(self.name, "not connected; call connect() first")

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def walk_together(drives: Sequence[Cia402Master], goal: State, first_words: Sequence[int],
                  command: Callable[[list[int]], list[int]], accept: tuple[State, ...] = ()) -> None:
    """Walk every drive of ``drives`` to ``goal`` (or a state in ``accept``) together: each
    ``command(words)`` exchange sends every drive its word and returns every statusword that
    answers (one SYNC on CANopen, one request per drive on Modbus), so no drive is left without
    its master while another walks; an arrived drive keeps getting the word that brought it there.
    :class:`DriveFault` as :class:`StateWalk` raises it."""
    walks = [StateWalk(drive, goal, word, accept) for drive, word in zip(drives, first_words)]
    words = list(first_words)
    walking = True
    while walking:
        statuswords = command(words)
        walking = False
        for i, (walk, statusword) in enumerate(zip(walks, statuswords)):
            walking |= walk.next_word(statusword) is not None
            words[i] = walk.word


def enable_together(drives: Sequence[Cia402Master], command: Callable[[list[int]], list[int]]) -> None:
    """Every drive of ``drives`` to OPERATION ENABLED in cyclic synchronous torque mode, walked
    together over ``command`` (:func:`walk_together`)."""
    for drive in drives:
        drive.prepare_enable()
    walk_together(drives, State.OPERATION_ENABLED, [drive.hold_word() for drive in drives], command)
    for drive in drives:
        drive.mark_enabled()


def disable_together(drives: Sequence[Cia402Master], command: Callable[[list[int]], list[int]]) -> None:
    """Zero torque and DISABLE VOLTAGE on every drive of ``drives``, walked together over ``command``
    to SWITCH ON DISABLED (or FAULT)."""
    for drive in drives:
        drive.mark_disabled()
    walk_together(drives, State.SWITCH_ON_DISABLED, [SAFE_CONTROLWORD] * len(drives), command, (State.FAULT,))


def trip_together(drives: Sequence[Cia402Master], error: DriveError) -> DriveError:
    """Trip every drive of ``drives`` not tripped yet (:meth:`~drives.cia402_master.Cia402Master.trip`, each its safe
    outputs): the one that met ``error`` with it, the others "stopped together with" it; returns
    ``error`` for ``raise`` (a master of several drives: one axis' fault stops every axis)."""
    for drive in drives:
        if drive.tripped is None:
            drive.trip(error if drive.name == error.node else
                       DriveError(drive.name, f"stopped together with {error.node}: {error.message}"))
    return error
