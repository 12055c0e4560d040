"""One drive's walk of the CiA-402 state machine towards a state, one controlword per exchange.

A master walks one drive with a :class:`StateWalk` (:meth:`~drives.cia402_master.Cia402Master._walk`);
a master of several drives walks them together, one exchange serving every walk
(:func:`~drives.axes_master.walk_together`).
"""

from __future__ import annotations

import time
from typing import Protocol

from drives.cia402 import CW_FAULT_RESET, Command, State, decode_statusword, path_to_operation_enabled, state_name
from drives.errors import DriveFault


class Walker(Protocol):
    """What a walk asks of its master: its name, how long one step may take (s, and in
    exchanges), and the error of a drive found in FAULT."""

    name: str
    state_timeout: float
    max_commands_per_step: int

    def in_fault(self, statusword: int) -> DriveFault: ...


class StateWalk:
    """One drive's walk of the CiA-402 state machine towards ``goal`` (or a state in ``accept``),
    one controlword per exchange, starting with ``first_word``.

    :meth:`next_word` takes the statusword that answered the last word sent and returns the next
    word to send, or None once the drive is there; it raises :class:`DriveFault` when the
    drive sits in FAULT on the way to an enabled state, or when one step stalls for the master's
    ``state_timeout`` (or ``max_commands_per_step`` exchanges).  ``word`` is the last word sent
    (what keeps an arrived drive where it is while others still walk), ``state`` the last seen.
    A master walks one drive with it (:meth:`Cia402Master._walk`); a master of several drives
    on one SYNC walks them together, one exchange serving every walk.
    """

    def __init__(self, master: Walker, goal: State, first_word: int, accept: tuple[State, ...] = ()) -> None:
        self.master = master
        self.goal = goal
        self.accept = accept
        self.word = first_word
        self.state: State | None = None
        self._step_started: float | None = None
        self._commands = 0

    @property
    def arrived(self) -> bool:
        """True once the last statusword showed ``goal`` or a state in ``accept``."""
        return self.state is self.goal or self.state in self.accept

    def next_word(self, statusword: int) -> int | None:
        """The controlword to send next, given the ``statusword`` that answered the last one; None when arrived."""
        master, goal = self.master, self.goal
        state = decode_statusword(statusword)
        now = time.monotonic()
        if self._step_started is None or state is not self.state:
            self.state, self._step_started, self._commands = state, now, 0
        if self.arrived:
            return None
        command: Command | None
        if goal is State.SWITCH_ON_DISABLED:
            command = Command.DISABLE_VOLTAGE
        elif state is State.FAULT:
            raise master.in_fault(statusword)
        else:
            path = path_to_operation_enabled(state) if state is not None else ()
            command = path[0] if path else None
        word = command.word if command is not None else self.word & ~CW_FAULT_RESET
        if now - self._step_started > master.state_timeout or self._commands > master.max_commands_per_step:
            sent = f"{command.name} (controlword 0x{word:04X})" if command is not None else f"controlword 0x{word:04X}"
            raise DriveFault(
                master.name,
                f"state machine stuck in {state_name(state)} (statusword 0x{statusword:04X}) for "
                f"{master.state_timeout:.3g} s while sending {sent} towards {goal.value}",
                state=state,
            )
        self._commands += 1
        self.word = word
        return word
