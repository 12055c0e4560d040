"""The supervisor names the drive whose input was not renewed in time (several axes: which one)."""

from __future__ import annotations

from haptic_bus.control.supervisor import Action, Supervisor, SupervisorPolicy

T = 1e-3  # s
NODES = ("CANopen node 5", "CANopen node 6", "CANopen node 7")


def _alarm_after_stale_cycles(stale_sources: list[int]) -> str:
    """Fresh cycles, then one input a sample old from each of ``stale_sources`` (axis indices) in turn
    until the 11th late cycle of the window raises the alarm: its message."""
    supervisor = Supervisor(SupervisorPolicy(on_late=Action.STOP.value), T, 1.0, NODES)
    for _ in range(20):
        assert supervisor.cycle(0.0, 0.0) == (False, None)
    for k in range(11):
        late, alarm = supervisor.cycle(0.0, 0.0, input_age=1, source=stale_sources[k % len(stale_sources)])
        assert late  # one sample old: 1 T beyond the assumed delay, more than the 0.5 T tolerated
        if alarm is not None:
            assert k == 10 and alarm.action is Action.STOP
            return alarm.message
    raise AssertionError("no alarm after 11 late cycles (the policy tolerates 10)")


def test_the_one_axis_that_did_not_renew_its_input_is_named() -> None:
    message = _alarm_after_stale_cycles([1])
    assert "(11 on an input CANopen node 6 did not renew in time; worst 1 ms at T = 1 ms)" in message, message


def test_every_axis_that_did_not_renew_an_input_in_the_window_is_named_once_in_axis_order() -> None:
    message = _alarm_after_stale_cycles([2, 0])
    assert "(11 on an input CANopen node 5, CANopen node 7 did not renew in time;" in message, message
