"""The bus-independent simulated drive: state machine, torque gating, units, exact response."""

from __future__ import annotations

import math

import pytest

from drives.cia402 import Command, State, _transitions, decode_statusword, transitions
from haptic_bus.analysis.plant import zoh_coefficients
from haptic_bus.errors import ParameterError
from sim_drive.device import ObjectAccessError, SimulatedDrive
from sim_drive.operator import ConstantPush, Sinusoid
from sim_drive.parameters import DeviceParameters, Timing

P = DeviceParameters()  # mass 0.5 kg, friction 0.1 N s/m, T 1 ms, 1e-6 m/s per count, 10 mN per per-mille


def walk(drive: SimulatedDrive, *commands: Command) -> None:
    for command in commands:
        drive.write_controlword(command.word)


def enabled(timing: Timing = Timing.CIA402, **kw: object) -> SimulatedDrive:
    drive = SimulatedDrive(DeviceParameters(**kw), timing)
    drive.write_object(0x6060, 10)
    walk(drive, Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION)
    assert drive.state is State.OPERATION_ENABLED
    return drive


def test_defaults_match_the_documented_scaling() -> None:
    assert P.scaling.newton_per_permille == pytest.approx(0.01, rel=1e-15)
    assert P.rated_torque_mnm == 200 and P.max_torque_permille == 3000 and P.cycle_period_us == 1000


def test_state_machine_walk_and_statusword() -> None:
    drive = SimulatedDrive()
    seen = []
    drive.state_listeners.append(lambda old, new, number: seen.append((new, number)))
    assert drive.state is State.SWITCH_ON_DISABLED
    steps = [
        (Command.SHUTDOWN, State.READY_TO_SWITCH_ON, 2),
        (Command.SWITCH_ON, State.SWITCHED_ON, 3),
        (Command.ENABLE_OPERATION, State.OPERATION_ENABLED, 4),
        (Command.DISABLE_OPERATION, State.SWITCHED_ON, 5),
        (Command.SHUTDOWN, State.READY_TO_SWITCH_ON, 6),
        (Command.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED, 7),
        (Command.SHUTDOWN, State.READY_TO_SWITCH_ON, 2),
        (Command.SWITCH_ON, State.SWITCHED_ON, 3),
        (Command.ENABLE_OPERATION, State.OPERATION_ENABLED, 4),
        (Command.SHUTDOWN, State.READY_TO_SWITCH_ON, 8),
    ]
    for command, state, number in steps:
        drive.write_controlword(command.word)
        assert drive.state is state, f"transition {number}"
        assert decode_statusword(drive.statusword) is state
        assert drive.read_object(0x6041) == drive.statusword
    assert seen == [(s, n) for _, s, n in steps]
    assert drive.statusword & 1 << 9  # remote
    assert drive.statusword & 1 << 4  # voltage enabled in READY TO SWITCH ON


def test_fault_and_reset_on_rising_edge_only() -> None:
    drive = enabled()
    drive.write_controlword(0x0F | 0x80)  # bit 7 high outside FAULT: masks the command
    assert drive.state is State.OPERATION_ENABLED
    drive.fault(0x1234)
    assert drive.state is State.FAULT and drive.read_object(0x603F) == 0x1234
    assert decode_statusword(drive.statusword) is State.FAULT
    drive.write_controlword(0x80)  # bit 7 was already high: no edge
    assert drive.state is State.FAULT
    drive.write_controlword(0x00)
    drive.write_controlword(0x80)  # rising edge
    assert drive.state is State.SWITCH_ON_DISABLED and drive.error_code == 0


@pytest.mark.parametrize("option, final", [(2, State.SWITCH_ON_DISABLED), (6, State.QUICK_STOP_ACTIVE)])
def test_quick_stop(option: int, final: State) -> None:
    drive = enabled()
    drive.write_object(0x605A, option)
    drive.write_object(0x6071, 500)
    drive.write_controlword(Command.QUICK_STOP.word)
    assert drive.state is State.QUICK_STOP_ACTIVE
    assert decode_statusword(drive.statusword) is State.QUICK_STOP_ACTIVE and drive.torque_actual == 0
    drive.sync()
    drive.sync()
    assert drive.state is final and drive.velocity == 0.0
    if option == 6:
        drive.write_controlword(Command.ENABLE_OPERATION.word)  # transition 16
        assert drive.state is State.OPERATION_ENABLED


@pytest.mark.parametrize(
    "setup",
    ["mode 0 (no mode)", "SWITCHED ON", "halt bit", "unsupported mode 9"],
)
def test_torque_is_zero_unless_operation_enabled_and_cst(setup: str) -> None:
    drive = SimulatedDrive()
    if setup == "unsupported mode 9":
        with pytest.raises(ObjectAccessError, match="range"):
            drive.write_object(0x6060, 9)  # refused (abort 0x06090030 on the bus): the mode stays 0
    elif setup != "mode 0 (no mode)":
        drive.write_object(0x6060, 10)
    walk(drive, Command.SHUTDOWN, Command.SWITCH_ON)
    if setup != "SWITCHED ON":
        drive.write_controlword(Command.ENABLE_OPERATION.word | (0x100 if setup == "halt bit" else 0))
    drive.write_object(0x6071, 1000)
    for _ in range(5):
        drive.sync()
    assert drive.velocity == 0.0 and drive.velocity_counts == 0 and drive.torque_actual == 0
    assert not drive.statusword & 1 << 12


@pytest.mark.parametrize("mode", [1, 8, 9, -3, 5])
def test_unsupported_modes_are_refused_and_change_nothing(mode: int) -> None:
    """CiA 402: 0x6060 takes the modes 0x6502 announces (and 0); anything else is a range error."""
    drive = SimulatedDrive()
    assert drive.read_object(0x6502) == 1 << 9
    drive.write_object(0x6060, 10)
    with pytest.raises(ObjectAccessError, match="range"):
        drive.write_object(0x6060, mode)
    assert (drive.read_object(0x6060), drive.read_object(0x6061)) == (10, 10)
    drive.write_object(0x6060, 0)
    assert (drive.read_object(0x6060), drive.read_object(0x6061)) == (0, 0)


@pytest.mark.parametrize("timing", list(Timing))
def test_saturation_at_max_torque(timing: Timing) -> None:
    drive = enabled(timing)
    drive.write_object(0x6071, 32767)
    drive.sync()
    drive.sync()
    assert drive.torque_actual == 3000  # saturated at 0x6072, never wrapped
    drive.write_object(0x6071, -32768)
    drive.sync()
    drive.sync()
    assert drive.torque_actual == -3000
    drive.write_object(0x6072, 100)
    drive.sync()
    drive.sync()
    assert drive.torque_actual == -100
    assert drive.parameters.max_torque_permille == 100


@pytest.mark.parametrize("timing", list(Timing))
def test_constant_torque_step_is_the_exact_first_order_response(timing: Timing) -> None:
    """Torque written after SYNC 0: v_k = (F/b)(1 - exp(-b k T/m)), one sample later in cia402."""
    drive = enabled(timing)
    drive.sync()  # SYNC 0
    drive.write_object(0x6071, 150)  # 1.5 N at the handle
    force = 150 * P.scaling.newton_per_permille
    shift = timing.delay
    for k in range(1, 400):
        drive.sync()
        n = max(k - shift, 0)
        exact = force / P.friction * -math.expm1(-P.friction * n * P.period / P.mass)
        # quantisation to the nearest count: within half a count (plus double rounding)
        assert abs(drive.velocity_counts * P.velocity_per_count - exact) <= 0.5 * P.velocity_per_count * (1 + 1e-9)
        assert drive.velocity == pytest.approx(exact, rel=1e-12, abs=1e-18)


def test_position_is_the_exact_integral_and_increments_are_rounded() -> None:
    drive = enabled(Timing.IDEAL)
    drive.sync()
    drive.write_object(0x6071, 100)
    for _ in range(50):
        drive.sync()
    co = zoh_coefficients(P.mass, P.friction, 50 * P.period)
    assert drive.position == pytest.approx(co.p_f * 1.0, rel=1e-12)
    assert drive.position_counts == round(drive.position / P.position_per_count)


def test_operator_and_wall_energy_are_exact() -> None:
    """Constant forces: sum(w dx) = w x and sum(u dx) = -F x exactly (x from rest at 0)."""
    drive = enabled(Timing.IDEAL, substeps=7)
    drive.set_operator(ConstantPush(2.0))
    drive.sync()
    drive.write_object(0x6071, -50)  # motor pushes back with 0.5 N
    for _ in range(300):
        drive.sync()
    assert drive.operator_energy == pytest.approx(2.0 * drive.position, rel=1e-12)
    assert drive.wall_energy == pytest.approx(0.5 * drive.position, rel=1e-12)
    assert drive.time == pytest.approx(0.3, rel=1e-12)


def test_substeps_reevaluate_the_operator_but_keep_zoh_exactness() -> None:
    one = SimulatedDrive(DeviceParameters(substeps=1), operator=ConstantPush(1.0))
    many = SimulatedDrive(DeviceParameters(substeps=10), operator=ConstantPush(1.0))
    wavy1 = SimulatedDrive(DeviceParameters(substeps=1), operator=Sinusoid(1.0, 300.0))
    wavy10 = SimulatedDrive(DeviceParameters(substeps=10), operator=Sinusoid(1.0, 300.0))
    for drive in (one, many, wavy1, wavy10):
        for _ in range(20):
            drive.sync()
    assert many.velocity == pytest.approx(one.velocity, rel=1e-12)  # held force: sub-steps compose exactly
    assert wavy10.velocity != pytest.approx(wavy1.velocity, rel=1e-3)  # varying force: sampled per sub-step


def test_velocity_counts_saturate_at_int32() -> None:
    drive = SimulatedDrive(DeviceParameters(velocity_per_count=1e-12), operator=ConstantPush(1000.0))
    for _ in range(100):
        drive.sync()
    assert drive.velocity_counts == 2**31 - 1


def test_object_access_errors() -> None:
    drive = SimulatedDrive()
    with pytest.raises(ObjectAccessError, match="unknown"):
        drive.read_object(0x1234)
    with pytest.raises(ObjectAccessError, match="read-only"):
        drive.write_object(0x6041, 0)
    with pytest.raises(ObjectAccessError, match="range"):
        drive.write_object(0x6071, 40000)
    with pytest.raises(ObjectAccessError, match="range"):
        drive.write_object(0x605A, 9)
    with pytest.raises(ObjectAccessError, match="range"):
        drive.write_object(0x6072, 70000)


def test_reconfigure_is_validated_and_nothing_half_applied() -> None:
    drive = SimulatedDrive()
    with pytest.raises(ParameterError, match="mass = -1"):
        drive.reconfigure(mass=-1.0, friction=0.2)
    assert drive.parameters == DeviceParameters()
    drive.write_object(0x6076, 300)
    assert drive.parameters.rated_torque == 0.3


@pytest.mark.parametrize(
    "field, value",
    [("mass", 0.0), ("friction", -0.1), ("period", 0.0), ("velocity_per_count", 0.0), ("rated_torque", 0.2005),
     ("max_torque_permille", 70000), ("substeps", 0), ("force_per_torque", float("nan"))],
)
def test_bad_parameters_raise_typed_errors(field: str, value: float) -> None:
    with pytest.raises(ParameterError, match=field):
        DeviceParameters(**{field: value})


def test_timing_can_be_changed_between_syncs() -> None:
    drive = SimulatedDrive(timing="ideal")
    assert drive.timing is Timing.IDEAL
    drive.timing = "cia402"
    assert drive.timing is Timing.CIA402 and Timing.CIA402.delay == 1


def test_saturate_never_wraps():
    from sim_drive.device import saturate

    assert saturate(40000, -3000, 3000) == 3000
    assert saturate(-40000, -3000, 3000) == -3000
    assert saturate(12, -3000, 3000) == 12


def test_a_controlwords_transitions_do_not_depend_on_what_was_asked_before() -> None:
    """transitions() is kept per argument: an entry answers only its own argument, type included.  A
    float controlword equal to an int one (15.0 == 15) is refused by the state machine's bit tests (a
    drive writing it raises); kept without its type, it took the int's answer once any drive had
    written 15 in that state, and a drive then held a float controlword."""
    _transitions.cache_clear()
    with pytest.raises(TypeError):
        transitions(State.SWITCHED_ON, 15.0, 7)  # type: ignore[arg-type]  # the refusal is what is tested
    assert transitions(State.SWITCHED_ON, 15, 7) == ((State.OPERATION_ENABLED, 4),)
    with pytest.raises(TypeError):
        transitions(State.SWITCHED_ON, 15.0, 7)  # type: ignore[arg-type]
    drive = SimulatedDrive()
    walk(drive, Command.SHUTDOWN, Command.SWITCH_ON)
    with pytest.raises(TypeError):
        drive.write_controlword(15.0)  # type: ignore[arg-type]
    assert (drive.state, drive.controlword) == (State.SWITCHED_ON, 0x0007)


def test_enable_operation_in_ready_to_switch_on_takes_transitions_3_and_4() -> None:
    drive = SimulatedDrive()
    seen: list[tuple[State, State, int | None]] = []
    drive.state_listeners.append(lambda old, new, number: seen.append((old, new, number)))
    drive.write_object(0x6060, 10)
    walk(drive, Command.SHUTDOWN, Command.ENABLE_OPERATION)  # 0x0006, then 0x000F
    assert drive.state is State.OPERATION_ENABLED
    assert seen == [(State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON, 2),
                    (State.READY_TO_SWITCH_ON, State.SWITCHED_ON, 3),
                    (State.SWITCHED_ON, State.OPERATION_ENABLED, 4)]


def test_statusword_bit_11_shows_the_torque_clamped_at_0x6072() -> None:
    drive = enabled()
    drive.write_object(0x6071, 3000)  # exactly the limit: not clamped
    assert not drive.statusword & 1 << 11
    drive.write_object(0x6071, -3001)
    assert drive.statusword & 1 << 11
    drive.sync()
    assert drive.torque_actual == -3000
    drive.write_object(0x6071, 12)
    assert not drive.statusword & 1 << 11


@pytest.mark.parametrize(("option", "state", "faulted"), [
    (0, State.OPERATION_ENABLED, False),
    (1, State.FAULT, True),
    (2, State.SWITCH_ON_DISABLED, False),
    (3, State.QUICK_STOP_ACTIVE, False),
])
def test_abort_connection_option_code_decides_the_reaction(option: int, state: State, faulted: bool) -> None:
    drive = enabled()
    drive.write_object(0x6007, option)
    drive.write_object(0x6071, 500)
    drive.sync()
    assert drive.connection_lost(0x8130) is faulted
    assert drive.state is state
    assert drive.read_object(0x603F) == (0x8130 if faulted else 0)
    assert drive.torque_actual == (500 if option == 0 else 0)  # the same cycle: no torque after the reaction


def test_connection_lost_does_nothing_without_the_power_stage() -> None:
    drive = SimulatedDrive()
    assert drive.connection_lost(0x8130) is False and drive.state is State.SWITCH_ON_DISABLED


@pytest.mark.parametrize("value", [-1, 4, 100])
def test_abort_connection_option_code_range(value: int) -> None:
    drive = SimulatedDrive()
    with pytest.raises(ObjectAccessError, match="range"):
        drive.write_object(0x6007, value)
    assert drive.read_object(0x6007) == 1  # the default: fault


def test_reset_application_restores_every_power_on_value() -> None:
    drive = enabled()
    drive.write_object(0x6072, 1200)
    drive.write_object(0x6076, 450)
    drive.write_object(0x6007, 3)
    drive.reconfigure(velocity_per_count=2e-6, mass=0.7)
    drive.reset_application()
    assert (drive.read_object(0x6072), drive.read_object(0x6076), drive.read_object(0x6007)) == (3000, 200, 1)
    assert drive.parameters == DeviceParameters()
    assert drive.state is State.SWITCH_ON_DISABLED and drive.read_object(0x6060) == 0
