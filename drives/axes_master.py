"""What a master of several CiA-402 drives does the same on every fieldbus.

:class:`AxesMaster` holds the drives, one per axis in axis order (at most :data:`MAX_AXES`), and
does what :class:`~drives.canopen.axes.CanopenAxes` (one SYNC) and
:class:`~drives.modbus.axes.ModbusAxes` (one poll) do alike: it connects every drive or none (on
any failure everything is closed again), walks their state machines together
(:func:`~drives.cia402_master.enable_together`: one exchange of every drive per step, the bus'
:meth:`AxesMaster._command`), takes the cyclic phase's torque limits one per axis, and refuses
use before :meth:`AxesMaster.connect` or after :meth:`AxesMaster.close`.  The bus' own part --
commissioning, the cyclic phase, the trip of every axis, the goodbye -- is the subclass'.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import Generic, Self, TypeVar

from drives.base import DriveScaling
from drives.cia402_master import Cia402Master, disable_together, enable_together
from drives.errors import DriveError, ParameterError

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
        if len(limits) != len(self.drives):
            raise ParameterError("torque_limits", len(limits), f"one per axis ({len(self.drives)})", self.name)
        return limits

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
