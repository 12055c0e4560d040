"""A running controller: :func:`haptic_bus.run` (what ``haptic-bus run`` runs) in a thread.

The run is the real one, of one axis or several, over CANopen or Modbus: it commissions the
drive(s) (the safety chain of the profile's ``[safety]``), serves gated wall uploads as CANopen
node ``controller_node_id`` (CANopen only), cycles under
its supervisor, leaves the drive disabled and writes its folder (``record.csv``, ``run.json``,
the plots if asked).  In virtual time (the default) the plant advances one period per SYNC, so a run of
``duration`` s of virtual time takes as long as the machine needs; real time paces it with the
wall clock.  Every wait on it is bounded in wall-clock time.
"""

from __future__ import annotations

import pathlib
import threading
import time
from typing import TYPE_CHECKING

import pytest

from haptic_bus.testing.run_files import RecordedRun, read_run_folder

if TYPE_CHECKING:
    from haptic_bus.app.profiles import AxesProfile, Profile
    from haptic_bus.app.runner import RunOptions, RunResult
    from haptic_bus.testing.simulated import SimDriveNode

# Bounds on a hang, not paces: 5x what this 2-core machine took with four CPU-bound processes beside the test at a
# load average of 11 (the README example's 1 s run, plots included, 67 s; a stop, the folder and plots written, 39 s).
RUN_WAIT = 600.0  # s of wall clock: the longest :meth:`ControllerRun.wait` waits for a run to end by itself
STOP_WAIT = 300.0  # s of wall clock: the longest a run is given to end once asked to stop
CYCLING_WAIT = 30.0  # s of wall clock: the longest :meth:`ControllerRun.wait_cycling` waits for the first cycle
MAX_WAIT = 86_400.0  # s of wall clock: the longest wait a test may ask for (a day: a run of hours fits)
ENABLED_ANSWERS = 2  # TPDOs in OPERATION ENABLED that prove a cycle: the enable walk's last, then the first cycle's


class ControllerRun:
    """One run of ``profile`` against ``node`` in a thread of this process, started on creation.

    ``folder``: where the run writes; ``result``: :class:`haptic_bus.app.runner.RunResult` once
    it has ended.  :meth:`wait` lets it end by itself, :meth:`stop` asks it to end at the next
    cycle (as SIGTERM does ``haptic-bus run``); both return the folder read back.
    """

    def __init__(self, profile: Profile | AxesProfile, node: SimDriveNode, options: RunOptions,
                 controller_node_id: int) -> None:
        if options.out_dir is None:
            raise ValueError("a controller run under test needs its folder (RunOptions.out_dir)")
        self.profile = profile
        self.node = node
        self.options = options
        self.controller_node_id = controller_node_id
        self.folder = pathlib.Path(options.out_dir)
        self.result: RunResult | None = None
        self.failure: BaseException | None = None  # an exception that escaped run (a bug, not a run's end)
        self._thread = threading.Thread(target=self._run, name=f"haptic-controller-{controller_node_id}", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from haptic_bus.app.runner import run

        try:
            self.result = run(self.profile, self.node.bus, self.options, controller_node_id=self.controller_node_id,
                              **self.node.run_kwargs())
        except BaseException as exc:  # handed to the test's thread by wait()/stop()
            self.failure = exc

    @property
    def running(self) -> bool:
        """True until the run has ended."""
        return self._thread.is_alive()

    def wait(self, timeout: float = RUN_WAIT) -> RecordedRun:
        """Wait at most ``timeout`` s of wall clock for the run to end by itself; its folder read
        back.  A run still going then is stopped and the test fails."""
        _check_timeout(timeout)
        self._thread.join(timeout)
        if self._thread.is_alive():
            self.stop()
            pytest.fail(f"the controller's run did not end within {timeout} s of wall clock (stopped it)")
        return self._ended()

    def stop(self, timeout: float = STOP_WAIT) -> RecordedRun:
        """Ask the run to end at the next cycle and wait at most ``timeout`` s; its folder read back
        (``exit_reason`` "stopped", or how it ended before).  A run that does not end fails the test."""
        _check_timeout(timeout)
        self.options.stop.event.set()
        self._thread.join(timeout)
        if self._thread.is_alive():
            pytest.fail(f"the controller's run did not stop within {timeout} s of being asked")
        return self._ended()

    def wait_cycling(self, timeout: float = CYCLING_WAIT) -> None:
        """Block until the controller cycles, at most ``timeout`` s: on CANopen every axis' TPDO1
        (statusword first) has reported OPERATION ENABLED twice, the enable walk's last exchange
        and the first cycle's; over Modbus every unit is OPERATION ENABLED and has had two cycles
        (output block writes) since; so the record will hold at least one cycle.  AssertionError if
        the run ends first (give the run a ``duration`` long enough to be seen, and :meth:`stop` it)."""
        _check_timeout(timeout)
        deadline = time.monotonic() + timeout
        spec = self.node.spec
        if spec is None:
            self._wait_modbus_cycling(deadline)
            return
        from drives.cia301 import TPDO_BASES
        from drives.cia402 import State, decode_statusword

        enabled = {TPDO_BASES[0] + node: 0 for node in (self.node.node_ids or (self.node.node_id,))}
        with spec.open() as bus:
            while time.monotonic() < deadline:
                message = bus.recv(0.1)
                if message is not None and message.arbitration_id in enabled and len(message.data) >= 2:
                    statusword = int.from_bytes(message.data[:2], "little")
                    enabled[message.arbitration_id] += decode_statusword(statusword) is State.OPERATION_ENABLED
                    if min(enabled.values()) >= ENABLED_ANSWERS:
                        return
                self._check_running()
        raise AssertionError(f"the drive did not answer a cycle in OPERATION ENABLED within {timeout} s on {spec}")

    def _wait_modbus_cycling(self, deadline: float) -> None:
        """:meth:`wait_cycling` over Modbus: the served units seen in this process, polled every 10 ms."""
        from drives.cia402 import State

        units = self.node.served_units()
        since: list[int | None] = [None] * len(units)
        while time.monotonic() < deadline:
            for i, unit in enumerate(units):
                if since[i] is None and unit.drive.state is State.OPERATION_ENABLED:
                    since[i] = unit.bank.cycles
            if all(start is not None and unit.bank.cycles >= start + ENABLED_ANSWERS for start, unit in zip(since, units)):
                return
            self._check_running()
            time.sleep(0.01)
        raise AssertionError(f"the Modbus units {self.node.unit_ids} did not cycle in OPERATION ENABLED in time")

    def _check_running(self) -> None:
        """AssertionError if the run has ended (before it was seen cycling)."""
        if not self.running:
            reason = self.result.exit_reason if self.result is not None else repr(self.failure)
            raise AssertionError(f"the controller's run ended ({reason}) before it was seen cycling")

    def _ended(self) -> RecordedRun:
        if self.failure is not None:
            failure, self.failure = self.failure, None
            raise failure
        return read_run_folder(self.folder)

    def close(self) -> None:
        """Teardown: stop the run if it still goes; an exception that escaped it and was never
        handed to the test fails the test now."""
        if self.running:
            self.stop()
        if self.failure is not None:
            raise AssertionError(f"the controller's run raised {self.failure!r}") from self.failure


def _check_timeout(timeout: object) -> None:
    """ParameterError for a wait that bounds nothing: ``wait(timeout=-1)`` returned at once and failed the test
    with "did not end within -1 s" (stopping a run that had just started); NaN and infinity likewise.  The
    project's one check of a real range (:func:`~haptic_bus.validation.real_in_range`), in its words."""
    from haptic_bus.validation import real_in_range

    real_in_range("timeout", timeout, 0.0, MAX_WAIT, low_inclusive=False, unit="s", context="haptic_controller run")
