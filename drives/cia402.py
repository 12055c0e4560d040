"""CiA-402 (IEC 61800-7-201) protocol tables shared by masters and simulated drives.

Object indices and types, the eight states decoded from the statusword, the controlword
commands, and the full transition table of the drive state machine.  Pure data and pure
functions: no bus code here.
"""

from __future__ import annotations

import enum
import functools
from dataclasses import dataclass

from drives.errors import ParameterError


class DataType(enum.Enum):
    """CANopen basic data types used by the CiA-402 objects (code, struct format)."""

    INTEGER8 = (0x0002, "b")
    INTEGER16 = (0x0003, "h")
    INTEGER32 = (0x0004, "i")
    UNSIGNED8 = (0x0005, "B")
    UNSIGNED16 = (0x0006, "H")
    UNSIGNED32 = (0x0007, "I")

    @property
    def code(self) -> int:
        """The CANopen data type index (0x0002..0x0007)."""
        return self.value[0]

    @property
    def struct_format(self) -> str:
        """The little-endian ``struct`` format character of one value."""
        return self.value[1]

    @property
    def size(self) -> int:
        """Size in bytes."""
        return {"b": 1, "B": 1, "h": 2, "H": 2, "i": 4, "I": 4}[self.struct_format]

    @property
    def range(self) -> tuple[int, int]:
        """Smallest and largest representable value."""
        bits = 8 * self.size
        if self.struct_format.islower():
            return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
        return 0, (1 << bits) - 1


@dataclass(frozen=True)
class ObjectSpec:
    """One CiA-402 object: index, subindex, type, access, name, unit."""

    index: int
    name: str
    data_type: DataType
    access: str
    unit: str = ""
    subindex: int = 0


ABORT_CONNECTION_OPTION_CODE = ObjectSpec(0x6007, "Abort connection option code", DataType.INTEGER16, "rw")
ERROR_CODE = ObjectSpec(0x603F, "Error code", DataType.UNSIGNED16, "ro")
CONTROLWORD = ObjectSpec(0x6040, "Controlword", DataType.UNSIGNED16, "rw")
STATUSWORD = ObjectSpec(0x6041, "Statusword", DataType.UNSIGNED16, "ro")
QUICK_STOP_OPTION_CODE = ObjectSpec(0x605A, "Quick stop option code", DataType.INTEGER16, "rw")
MODES_OF_OPERATION = ObjectSpec(0x6060, "Modes of operation", DataType.INTEGER8, "rw")
MODES_OF_OPERATION_DISPLAY = ObjectSpec(0x6061, "Modes of operation display", DataType.INTEGER8, "ro")
POSITION_ACTUAL = ObjectSpec(0x6064, "Position actual value", DataType.INTEGER32, "ro", "increments")
VELOCITY_ACTUAL = ObjectSpec(0x606C, "Velocity actual value", DataType.INTEGER32, "ro", "velocity units")
TARGET_TORQUE = ObjectSpec(0x6071, "Target torque", DataType.INTEGER16, "rw", "per mille of rated torque")
MAX_TORQUE = ObjectSpec(0x6072, "Max torque", DataType.UNSIGNED16, "rw", "per mille of rated torque")
MOTOR_RATED_TORQUE = ObjectSpec(0x6076, "Motor rated torque", DataType.UNSIGNED32, "rw", "mN m")
TORQUE_ACTUAL = ObjectSpec(0x6077, "Torque actual value", DataType.INTEGER16, "ro", "per mille of rated torque")
SUPPORTED_DRIVE_MODES = ObjectSpec(0x6502, "Supported drive modes", DataType.UNSIGNED32, "ro")

OBJECTS: dict[int, ObjectSpec] = {
    spec.index: spec
    for spec in (
        ABORT_CONNECTION_OPTION_CODE,
        ERROR_CODE,
        CONTROLWORD,
        STATUSWORD,
        QUICK_STOP_OPTION_CODE,
        MODES_OF_OPERATION,
        MODES_OF_OPERATION_DISPLAY,
        POSITION_ACTUAL,
        VELOCITY_ACTUAL,
        TARGET_TORQUE,
        MAX_TORQUE,
        MOTOR_RATED_TORQUE,
        TORQUE_ACTUAL,
        SUPPORTED_DRIVE_MODES,
    )
}


@dataclass(frozen=True)
class RatioSpec:
    """A factor-group ARRAY of CiA-402: sub 1 ``numerator`` / sub 2 ``denominator``, both UNSIGNED32 > 0."""

    index: int
    name: str
    numerator: str
    denominator: str
    data_type: DataType = DataType.UNSIGNED32


# The factor group (CiA-402 / IEC 61800-7-201) and the SI unit objects: how the drive's position
# and velocity units relate to its encoder, its gearbox and the feed of its mechanics.
# :mod:`drives.factor_group` turns them into SI; none of them is in OBJECTS (not every drive has them).
POSITION_ENCODER_RESOLUTION = RatioSpec(0x608F, "Position encoder resolution", "Encoder increments", "Motor revolutions")
VELOCITY_ENCODER_RESOLUTION = RatioSpec(0x6090, "Velocity encoder resolution", "Encoder increments per second",
                                        "Motor revolutions per second")
GEAR_RATIO = RatioSpec(0x6091, "Gear ratio", "Motor revolutions", "Shaft revolutions")
FEED_CONSTANT = RatioSpec(0x6092, "Feed constant", "Feed", "Shaft revolutions")
RATIO_OBJECTS: tuple[RatioSpec, ...] = (POSITION_ENCODER_RESOLUTION, VELOCITY_ENCODER_RESOLUTION, GEAR_RATIO, FEED_CONSTANT)
SI_UNIT_POSITION = ObjectSpec(0x60A8, "SI unit position", DataType.UNSIGNED32, "rw")
SI_UNIT_VELOCITY = ObjectSpec(0x60A9, "SI unit velocity", DataType.UNSIGNED32, "rw")
UNIT_OBJECTS: tuple[ObjectSpec, ...] = (SI_UNIT_POSITION, SI_UNIT_VELOCITY)


class OperationMode(enum.IntEnum):
    """Values of 0x6060/0x6061."""

    PROFILE_POSITION = 1
    VELOCITY = 2
    PROFILE_VELOCITY = 3
    PROFILE_TORQUE = 4
    HOMING = 6
    INTERPOLATED_POSITION = 7
    CYCLIC_SYNCHRONOUS_POSITION = 8
    CYCLIC_SYNCHRONOUS_VELOCITY = 9
    CYCLIC_SYNCHRONOUS_TORQUE = 10

    @classmethod
    def of(cls, value: int) -> OperationMode:
        """``value`` (0x6060's code) as a mode; :class:`~drives.errors.ParameterError` naming the codes if it is none."""
        try:
            if isinstance(value, bool):  # True is 1 to int(), not a code anyone means
                raise ValueError(value)
            return cls(value)
        except ValueError:
            allowed = ", ".join(f"{int(m)} ({m.name})" for m in cls)
            raise ParameterError("mode of operation (0x6060)", value, allowed) from None

    @property
    def supported_bit(self) -> int:
        """The bit of 0x6502 that announces support of this mode: bit ``mode - 1`` (bit 4, for the
        reserved mode 5, stays reserved)."""
        return int(self) - 1


def _enum_text(kind: type[enum.IntEnum], value: int, what: str) -> str:
    """``value`` of a CiA-402 code object in words; negative values are the manufacturer's (CiA-402)."""
    if value < 0:
        return f"manufacturer-specific {what}"
    try:
        return kind(value).name.lower().replace("_", " ")
    except ValueError:
        return f"reserved {what}"


def describe_mode(value: int) -> str:
    """A 0x6060/0x6061 value in words: ``"cyclic synchronous torque"``, ``"no mode"``, ``"reserved mode"``."""
    return "no mode" if value == 0 else _enum_text(OperationMode, value, "mode")


def supports(supported_drive_modes: int, mode: OperationMode) -> bool:
    """True if the 0x6502 bit field announces ``mode``."""
    return bool(supported_drive_modes >> mode.supported_bit & 1)


def cst_announced(supported_drive_modes: int | None) -> bool | None:
    """Whether 0x6502 announces cyclic synchronous torque (bit 9); None where it was not read."""
    return None if supported_drive_modes is None else supports(supported_drive_modes, OperationMode.CYCLIC_SYNCHRONOUS_TORQUE)


class State(enum.Enum):
    """The eight states of the CiA-402 power drive system."""

    NOT_READY_TO_SWITCH_ON = "NOT READY TO SWITCH ON"
    SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
    READY_TO_SWITCH_ON = "READY TO SWITCH ON"
    SWITCHED_ON = "SWITCHED ON"
    OPERATION_ENABLED = "OPERATION ENABLED"
    QUICK_STOP_ACTIVE = "QUICK STOP ACTIVE"
    FAULT_REACTION_ACTIVE = "FAULT REACTION ACTIVE"
    FAULT = "FAULT"


# (mask, value, state) per CiA-402 table 30; the first match wins.
_STATUS_PATTERNS: tuple[tuple[int, int, State], ...] = (
    (0x4F, 0x00, State.NOT_READY_TO_SWITCH_ON),
    (0x4F, 0x40, State.SWITCH_ON_DISABLED),
    (0x6F, 0x21, State.READY_TO_SWITCH_ON),
    (0x6F, 0x23, State.SWITCHED_ON),
    (0x6F, 0x27, State.OPERATION_ENABLED),
    (0x6F, 0x07, State.QUICK_STOP_ACTIVE),
    (0x4F, 0x0F, State.FAULT_REACTION_ACTIVE),
    (0x4F, 0x08, State.FAULT),
)

# The statusword bits 0-6 each state shows (bit 5 "quick stop" is 1 where not active).
STATE_STATUS_BITS: dict[State, int] = {state: value for _, value, state in _STATUS_PATTERNS}

SW_FAULT = 1 << 3
SW_VOLTAGE_ENABLED = 1 << 4
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT_ACTIVE = 1 << 11
SW_FOLLOWS_COMMAND = 1 << 12  # the cyclic synchronous modes: the drive follows the command value (0x6071 in CST)
SW_STATE_MASK = 0x6F


def decode_statusword(statusword: int) -> State | None:
    """The state a statusword shows, or None for a pattern the standard does not define."""
    for mask, value, state in _STATUS_PATTERNS:
        if statusword & mask == value:
            return state
    return None


class Command(enum.Enum):
    """Device control commands of the controlword: (mask, value) of bits 0-3 and 7."""

    SHUTDOWN = (0x87, 0x06)
    SWITCH_ON = (0x8F, 0x07)
    DISABLE_VOLTAGE = (0x82, 0x00)
    QUICK_STOP = (0x86, 0x02)
    DISABLE_OPERATION = (0x8F, 0x07)
    ENABLE_OPERATION = (0x8F, 0x0F)
    FAULT_RESET = (0x80, 0x80)

    @property
    def word(self) -> int:
        """The controlword a master writes for this command."""
        return self.value[1]

    def matches(self, controlword: int) -> bool:
        """True if ``controlword`` carries this command."""
        mask, value = self.value
        return controlword & mask == value


def state_name(state: State | None) -> str:
    """The state's CiA-402 name, or a phrase for a statusword the standard does not define."""
    return state.value if state is not None else "an undefined state"


SAFE_CONTROLWORD = Command.DISABLE_VOLTAGE.word  # -> SWITCH ON DISABLED: no torque, the handle free


class AbortConnectionOption(enum.IntEnum):
    """Values of 0x6007: what the drive does when the connection to its master aborts
    (heartbeat or RPDO deadline lost, NMT out of OPERATIONAL while the power stage is on)."""

    NO_ACTION = 0
    FAULT = 1
    DISABLE_VOLTAGE = 2
    QUICK_STOP = 3


def describe_abort_option(value: int) -> str:
    """A 0x6007 value in words: ``"fault"``, ``"no action"``, ``"reserved option"``."""
    return _enum_text(AbortConnectionOption, value, "option")


CW_FAULT_RESET = 1 << 7
CW_HALT = 1 << 8


@dataclass(frozen=True)
class Transition:
    """One numbered transition of the CiA-402 state machine."""

    number: int
    source: State
    target: State
    commands: tuple[Command, ...]


# Transitions driven by the controlword (CiA-402 figure 14).  0, 1 and 14 are internal
# (power-up and fault reaction completion); 13 is "a fault occurred", from any state.
TRANSITIONS: tuple[Transition, ...] = (
    Transition(2, State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON, (Command.SHUTDOWN,)),
    Transition(3, State.READY_TO_SWITCH_ON, State.SWITCHED_ON, (Command.SWITCH_ON,)),
    Transition(4, State.SWITCHED_ON, State.OPERATION_ENABLED, (Command.ENABLE_OPERATION,)),
    Transition(5, State.OPERATION_ENABLED, State.SWITCHED_ON, (Command.DISABLE_OPERATION,)),
    Transition(6, State.SWITCHED_ON, State.READY_TO_SWITCH_ON, (Command.SHUTDOWN,)),
    Transition(7, State.READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED, (Command.QUICK_STOP, Command.DISABLE_VOLTAGE)),
    Transition(8, State.OPERATION_ENABLED, State.READY_TO_SWITCH_ON, (Command.SHUTDOWN,)),
    Transition(9, State.OPERATION_ENABLED, State.SWITCH_ON_DISABLED, (Command.DISABLE_VOLTAGE,)),
    Transition(10, State.SWITCHED_ON, State.SWITCH_ON_DISABLED, (Command.DISABLE_VOLTAGE, Command.QUICK_STOP)),
    Transition(11, State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, (Command.QUICK_STOP,)),
    Transition(12, State.QUICK_STOP_ACTIVE, State.SWITCH_ON_DISABLED, (Command.DISABLE_VOLTAGE,)),
    Transition(16, State.QUICK_STOP_ACTIVE, State.OPERATION_ENABLED, (Command.ENABLE_OPERATION,)),
)

TRANSITION_FAULT = 13
TRANSITION_FAULT_REACTION_DONE = 14
TRANSITION_FAULT_RESET = 15


def transitions(
    state: State, controlword: int, previous_controlword: int, *, quick_stop_option_code: int = 2
) -> tuple[tuple[State, int], ...]:
    """The transitions one controlword write takes from ``state``: ``(new state, number)`` in order.

    Fault reset (15) acts on the rising edge of bit 7 only.  Transition 16 (quick stop back
    to operation enabled) exists only for quick stop option codes 5..8, as the standard says.
    ENABLE OPERATION in READY TO SWITCH ON takes transitions 3 and 4 (the standard's
    "automatic" transition through SWITCHED ON).  A command that has no transition from
    ``state`` takes none (an empty tuple).
    """
    return _transitions(state, controlword, previous_controlword, quick_stop_option_code)


@functools.lru_cache(maxsize=1024, typed=True)
def _transitions(state: State, controlword: int, previous_controlword: int,
                 quick_stop_option_code: int) -> tuple[tuple[State, int], ...]:
    """:func:`transitions`, kept per argument (a drive's every cycle writes the same controlword in
    the same state: 4.5 us of matching each time, 0.5 us kept), type included: 15.0 == 15, but a float
    controlword is refused by the bit tests, and must not take an int's kept answer."""
    if state is State.FAULT:
        rising = controlword & CW_FAULT_RESET and not previous_controlword & CW_FAULT_RESET
        return ((State.SWITCH_ON_DISABLED, TRANSITION_FAULT_RESET),) if rising else ()
    if controlword & CW_FAULT_RESET:
        return ()  # bit 7 high outside FAULT masks the other commands
    if state is State.READY_TO_SWITCH_ON and Command.ENABLE_OPERATION.matches(controlword):
        return (State.SWITCHED_ON, 3), (State.OPERATION_ENABLED, 4)
    for transition in TRANSITIONS:
        if transition.source is not state:
            continue
        if transition.number == 16 and not 5 <= quick_stop_option_code <= 8:
            continue
        if any(command.matches(controlword) for command in transition.commands):
            return ((transition.target, transition.number),)
    return ()


def path_to_operation_enabled(state: State) -> tuple[Command, ...]:
    """The commands a master sends, in order, to walk from ``state`` to OPERATION ENABLED."""
    paths = {
        State.FAULT: (Command.FAULT_RESET, Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION),
        State.SWITCH_ON_DISABLED: (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION),
        State.READY_TO_SWITCH_ON: (Command.SWITCH_ON, Command.ENABLE_OPERATION),
        State.SWITCHED_ON: (Command.ENABLE_OPERATION,),
        State.QUICK_STOP_ACTIVE: (Command.DISABLE_VOLTAGE, Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION),
        State.OPERATION_ENABLED: (),
    }
    return paths.get(state, ())
