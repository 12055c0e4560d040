"""The supervisor's derate, prepared before a run of one axis or several: for delays beyond the
assumed one, the largest scale of the scene the gate still passes (the control loop never waits
for the gate).

One search for either gate: the 1-D :class:`~haptic_bus.control.gate.PassivityGate` with its
compiled scene, or the coupled :class:`~haptic_bus.control.space_gate.SpaceGate` with a scene in
space (each gate's ``later``, ``passes``, ``passive_scales`` and ``judge``; each scene's
``scaled``).  The passive scales (margin >= 0) bound the search; inside the highest interval whose
lower end the gate accepts, a bisection finds where the policy's safety margin is last met, and
the scaled scene is judged whole.

Where it runs: the 1-D gate judges a scaled scene in microseconds, so its table is built at once
with :data:`DERATE_SCALE_STEPS` steps.  The coupled gate judges a scene with a sphere in seconds
(a search over directions), so its table is built in the judge worker process
(:func:`haptic_bus.node.verdicts.judge_pool`, started before the cycles), one delay after
another, with :data:`COUPLED_SCALE_STEPS` steps (a scale within 1/256 below the largest); an
entry serves an alarm only once it is built, and an alarm before that finds none: the supervisor
stops the run, as beyond the table.

Units: loop delays in samples, scales dimensionless in (0, 1].
"""

from __future__ import annotations

from concurrent.futures import Executor, Future, ProcessPoolExecutor
from typing import Any

from haptic_bus.control.supervisor import Action, SupervisorPolicy

DERATE_SCALE_STEPS = 40  # bisection steps of the 1-D derate's margin search inside a passive interval: 2^-40
COUPLED_SCALE_STEPS = 8  # ... of the coupled gate's, whose every judgement of a sphere costs seconds: 2^-8
DERATE_EXTRA_DELAYS = (0.25, 0.5, 1.0, 2.0, 3.0)  # samples beyond the assumed delay a derated scene is prepared for

Entry = tuple[Any, Any, Any] | None  # (the gate at that delay, the scaled scene, its decision), or None: no scale passes


def asks_derate(policy: SupervisorPolicy) -> bool:
    """Whether the supervisor's policy derates on an alarm (then a run prepares the table)."""
    return Action.DERATE.value in (policy.on_late, policy.on_observer)


class DerateTable:
    """The supervisor's derate (module docstring): for each loop delay :data:`DERATE_EXTRA_DELAYS`
    beyond the longest one ``gate`` assumes, the largest scale of ``scene`` the gate at that delay
    passes, judged again whole; built now, or by ``pool`` (each delay one task, in order).  Called
    with the running scene and an observed delay (samples), it gives the first built entry at or
    above that delay; beyond the table, or before any entry at or above it is built, None (the
    supervisor stops, and :meth:`shortfall` says which)."""

    def __init__(self, gate: Any, scene: Any, steps: int = DERATE_SCALE_STEPS, pool: Executor | None = None) -> None:
        assumed = max(loop.delay for loop in gate.axes)
        self._pool = pool
        self._table: list[tuple[float, Future[Entry]]] = []
        for extra in DERATE_EXTRA_DELAYS:
            if pool is not None:
                self._table.append((assumed + extra, pool.submit(largest_passing_scale, gate.later(extra), scene, steps)))
                continue
            built: Future[Entry] = Future()
            built.set_result(largest_passing_scale(gate.later(extra), scene, steps))
            self._table.append((assumed + extra, built))

    @property
    def entries(self) -> tuple[tuple[float, Future[Entry]], ...]:
        """The table: each prepared loop delay (samples) and its entry, built or to be built."""
        return tuple(self._table)

    def __call__(self, running: Any, observed_delay: float) -> Entry:
        return next((entry.result() for delay, entry in self._table if delay >= observed_delay and _built(entry)), None)

    def shortfall(self, observed_delay: float) -> str:
        """Why the table has no derated scene for ``observed_delay`` samples (what :meth:`__call__` gave None for)."""
        longest = self._table[-1][0]
        if observed_delay > longest:
            return f"beyond the derate table (prepared up to a loop delay of {longest:g} samples)"
        built = sum(_built(entry) for _, entry in self._table)
        if all(_built(entry) for delay, entry in self._table if delay >= observed_delay):
            return "no scale of the scene passes the gate at that delay"
        return (f"the derate table was not ready: {built} of {len(self._table)} entries built (the judge "
                "worker builds them one after another from the run's start; the coupled gate takes seconds each)")

    def abandon(self) -> None:
        """The run has ended: no entry still to be built is waited for.  In a worker process
        the worker is killed (:func:`~haptic_bus.node.verdicts.kill_workers`) and every such entry
        fails with BrokenProcessPool (cancelling some first would race the executor's own clean-up,
        which then sets an exception on a cancelled future); elsewhere they are cancelled."""
        waiting = [entry for _, entry in self._table if not entry.done()]
        if not waiting:
            return
        if isinstance(self._pool, ProcessPoolExecutor):
            from haptic_bus.node.verdicts import kill_workers

            kill_workers(self._pool)
            return
        for entry in waiting:
            entry.cancel()


def _built(entry: Future[Entry]) -> bool:
    """Whether ``entry`` holds its result (not pending, not given up, not failed)."""
    return entry.done() and not entry.cancelled() and entry.exception() is None


def largest_passing_scale(gate: Any, scene: Any, steps: int) -> Entry:
    """The scene scaled by the largest ``s`` in (0, 1] that ``gate`` accepts (within ``2^-steps`` below
    it), with ``gate`` and its decision, or None.

    The passive scales are the gate's intervals (``passive_scales``); inside the highest one whose
    lower end the gate accepts, a bisection finds where the policy's safety margin is last met.
    """
    if gate.passes(scene):
        return gate, scene, gate.admit(scene)
    for low, high in reversed(gate.passive_scales(scene)):
        low = max(low, 2.0 ** -steps)  # scale 0 is no wall at all: not a derate
        if low > high or not gate.passes(scene.scaled(low)):
            continue
        for _ in range(steps):
            middle = 0.5 * (low + high)
            low, high = (middle, high) if gate.passes(scene.scaled(middle)) else (low, middle)
        scaled = scene.scaled(low)
        decision = gate.judge(scaled)
        if decision.accepted:
            return gate, scaled, decision
    return None
