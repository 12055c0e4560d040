"""What every ``haptic-bus`` subcommand parses the same way: exit statuses, the one-line parser,
the help formatter, the argument types (numbers with their ranges, node and unit ids, Modbus
URLs, python-can bus options) and the registration of a subcommand.

Only light modules are imported here (no numpy, scipy, canopen, pymodbus): building the whole
parser must cost little more than starting Python.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable
from typing import Any, TypeVar

from drives.bus_config import BUS_KWARGS_HELP, BUS_OPTION_HELP, as_typed, merge_bus_options, parse_bus_option
from drives.cia301 import NODE_ID_RANGE, NODE_IDS
from drives.modbus.register_map import UNIT_ID_RANGE, UNIT_IDS
from haptic_bus.analysis.loop import (
    DAMPING_RANGE,
    DELAY_RANGE,
    FRICTION_RANGE,
    MASS_RANGE,
    PERIOD_RANGE,
    STIFFNESS_RANGE,
)
from haptic_bus.errors import ParameterError
from haptic_bus.validation import ids_in_order, real_in_range, real_range

N = TypeVar("N", int, float)

EXIT_OK, EXIT_NO, EXIT_INVALID, EXIT_ASSUMPTION, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
Handler = Callable[[argparse.Namespace], int]


_REQUIRED = "the following arguments are required: "  # argparse's words for required arguments left out


class _AsTyped(str):
    """A number's text as the user typed it, shown bare in a refusal (``repr`` quotes a str)."""

    def __repr__(self) -> str:
        return str(self)


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr and exit status 2, and an argument no option
    takes is the usage error of the (sub)command given (:meth:`parse_command`).  A negative number in
    scientific notation (``--position-resolution -1e-6``) is a value, as Python 3.13's argparse reads it,
    so its check names the range; 3.11's took it for an option ("expected one argument")."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"-\.?\d")  # argparse's own test, as of Python 3.13

    def _get_value(self, action: argparse.Action, arg_string: str) -> Any:
        """argparse's, but a type's :class:`~haptic_bus.errors.ParameterError` is the usage error naming the flag
        once, ``--unit-id = 0 is invalid; allowed: ...`` (argparse's own line named it twice, ``argument --unit-id:
        unit id = 0 ...``, or, the ParameterError being a ValueError, said ``invalid parse value``); a positional
        argument keeps the type's name.  The value is shown as typed (``-1e-5``, ``0x80``, not the number read
        from it, ``-1e-05``, ``128``), text that is no number quoted (``'x'``)."""
        try:
            return super()._get_value(action, arg_string)
        except argparse.ArgumentError as error:
            refused = error.__context__  # what the type raised, which argparse's ArgumentError replaced
            if not isinstance(refused, ParameterError):
                raise
            name = max(action.option_strings, key=len) if action.option_strings else refused.name
            typed = arg_string if isinstance(refused.value, str) else _AsTyped(arg_string)
            raise argparse.ArgumentError(None, ParameterError(name, typed, refused.allowed).detail) from None

    def error(self, message: str) -> None:  # type: ignore[override]
        if message.startswith(_REQUIRED):
            message = self._missing(message.removeprefix(_REQUIRED).split(", ")[0])
        self.exit(EXIT_INVALID, f"{self.prog}: error: {message}\n")

    def _missing(self, name: str) -> str:
        """argparse's "the following arguments are required: NAME, ..." said as every command says a value not
        given (:class:`~haptic_bus.errors.ParameterError`'s rule): ``NAME is missing; allowed: HELP``, the first
        one named, a subcommand as ``a command is missing; allowed: one of A, B``."""
        if name.startswith("{"):
            return f"a command is missing; allowed: one of {name.strip('{}').replace(',', ', ')}"
        for action in self._actions:
            if name in (*action.option_strings, action.metavar, action.dest) and action.help:
                return str(ParameterError(name, None, action.help))
        return str(ParameterError(name, None, f"see {self.prog} --help"))

    def parse_command(self, argv: list[str]) -> argparse.Namespace:
        """``argv`` parsed; a stray argument is the usage error of the deepest subcommand given
        (``haptic-bus profiles list: error: unrecognized arguments: ...``), where argparse's own names only the top."""
        args, extra = self.parse_known_args(argv)
        if extra:
            self._chosen(args).error(f"unrecognized arguments: {' '.join(extra)}")
        return args

    def _chosen(self, args: argparse.Namespace) -> argparse.ArgumentParser:
        """The (sub)command ``args`` chose under this parser, down to its last level (``profiles list``)."""
        parser: argparse.ArgumentParser = self
        while True:
            commands = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)  # argparse's table
            choice = None if commands is None else getattr(args, commands.dest, None)
            if commands is None or choice is None:
                return parser
            parser = commands.choices[choice]


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Help that shows every default (once: not where the help text states it, nor an unset one)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        unset = action.default is None or action.default is False or action.default == []
        if unset or "default" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


# --------------------------------------------------------------------------- argument types

def number(name: str, low: float, high: float, unit: str, *, low_open: bool = False) -> Callable[[str], float]:
    """A parser of a finite real in ``[low, high]`` (``(low, high]`` with ``low_open``), in ``unit``, checked by
    :func:`~haptic_bus.validation.real_in_range` (its ParameterError names ``name``; a flag's, the flag:
    :class:`OneLineParser`)."""

    def parse(text: str) -> float:
        try:
            value: object = float(text)
        except ValueError:  # not a number: the range too, in the one line (break16)
            value = text
        return real_in_range(name, value, low, high, low_inclusive=not low_open, unit=unit)

    return parse


def whole(name: str, low: int, high: int, allowed: str = "") -> Callable[[str], int]:
    """A parser of an integer in ``low..high`` (decimal, or 0x.. hexadecimal); its refusal says ``allowed``
    (default ``an integer low..high``; a node or unit id: its table's words, ``CANopen node ids 1..127``)."""
    allowed = allowed or f"an integer {low}..{high}"

    def parse(text: str) -> int:
        try:
            value = int(text, 0)
        except ValueError:  # not an integer: the range too, in the one line (break16)
            raise ParameterError(name, text, f"{allowed} (decimal, or 0x-hexadecimal)") from None
        if not low <= value <= high:
            raise ParameterError(name, value, allowed)
        return value

    return parse


# what the analysis allows (haptic_bus.analysis.loop's ranges), for a flag's text that is no number at all
MASS_ALLOWED = real_range(*MASS_RANGE, "kg")
FRICTION_ALLOWED = real_range(*FRICTION_RANGE, "N s/m")
PERIOD_ALLOWED = real_range(*PERIOD_RANGE, "s")
STIFFNESS_ALLOWED = real_range(*STIFFNESS_RANGE, "N/m")
DAMPING_ALLOWED = real_range(*DAMPING_RANGE, "N s/m")
DELAY_ALLOWED = real_range(*DELAY_RANGE, "samples")


def a_real(name: str, allowed: str) -> Callable[[str], float]:
    """A parser of a real number whose range a later check owns (the analysis, the gate): text that is no
    number is refused naming ``allowed`` (argparse's own line, ``invalid float value: 'x'``, named none);
    ``nan``/``inf`` parse, for that check to refuse with its range."""
    return _read_as(float, name, allowed)


def an_integer(name: str, allowed: str) -> Callable[[str], int]:
    """:func:`a_real` for an integer (decimal)."""
    return _read_as(int, name, allowed)


def _read_as(kind: Callable[[str], N], name: str, allowed: str) -> Callable[[str], N]:
    """A parser of text as ``kind`` (``float``, ``int``); text it cannot read is one line naming ``allowed``."""

    def parse(text: str) -> N:
        try:
            return kind(text)
        except ValueError:
            raise ParameterError(name, text, allowed) from None

    return parse


seconds = number("duration", 0.0, 1e7, "s", low_open=True)
timeout = number("timeout", 0.0, 3600.0, "s", low_open=True)
node_id = whole("node id", *NODE_ID_RANGE, NODE_IDS)
unit_id = whole("unit id", *UNIT_ID_RANGE, UNIT_IDS)


def unit_ids(text: str) -> str:
    """``1,2,3``: Modbus unit ids, one per axis in axis order, checked as
    :func:`~haptic_bus.validation.ids_in_order` reads them and kept as text: whether they must be
    distinct depends on the servers (``--modbus`` once: yes; once per axis: unit 1 may serve each),
    known once every option is read, and that refusal names what was typed."""
    ids_in_order("unit ids", text, UNIT_IDS, *UNIT_ID_RANGE)
    return text


def modbus_url(text: str) -> str:
    """``tcp://HOST:PORT`` (port 1..65535) or ``rtu:/dev/...``."""
    from drives.modbus.link import ModbusAddress

    ModbusAddress.from_url(text)
    return text



# --------------------------------------------------------------------------- shared options

def add_bus_arguments(parser: argparse.ArgumentParser) -> None:
    """The python-can bus options: ``--interface``, ``--channel``, ``--bitrate``, ``--bus-option``."""
    parser.add_argument("--interface", help="python-can interface (socketcan, virtual, udp_multicast, ...)")
    parser.add_argument("--channel", help="python-can channel (can0, vcan0, a multicast group, ...)")
    parser.add_argument("--bitrate", type=an_integer("bitrate", "a positive whole number of bit/s"), help="bit/s")
    parser.add_argument("--bus-option", type=parse_bus_option, action="append", default=[], metavar="KEY=VALUE",
                        help=BUS_OPTION_HELP)
    parser.add_argument("--bus-kwargs", type=parse_bus_option, nargs="+", action="append", default=[], metavar="KEY=VALUE",
                        help=BUS_KWARGS_HELP)


def bus_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The ``can.Bus`` keywords the bus options gave (the rest from python-can's configuration);
    ParameterError for a key given twice with different values."""
    named = [(key, getattr(args, key)) for key in ("interface", "channel", "bitrate") if getattr(args, key) is not None]
    return merge_bus_options(named, args.bus_option, *args.bus_kwargs)


def refuse_can_options_with_modbus(args: argparse.Namespace, command: str, others: tuple[str, ...] = (),
                                   modbus_options: str = "--unit-id") -> None:
    """ParameterError naming the first CAN bus option (or one of ``others``, argparse dests) given beside ``--modbus``."""

    given = [dest for dest in ("interface", "channel", "bitrate", "bus_option", "bus_kwargs", *others) if getattr(args, dest)]
    if given:
        raise ParameterError("--" + given[0].replace("_", "-"), as_typed(getattr(args, given[0])),
                             f"only Modbus options ({modbus_options}) with --modbus", command)




def error_line(command: str, error: Exception) -> str:
    """``haptic-bus COMMAND: error: ...``, one line; a :class:`ParameterError` whose context is the command
    itself ("run", "profiles new") says it once, in front, not twice."""

    if isinstance(error, ParameterError) and error.context.split(" ")[0] == command.split(" ")[0]:
        return f"haptic-bus {error.context}: error: {error.detail}"
    if isinstance(error, ParameterError) and error.context in SHARED_CONTEXTS:  # demo's --out checked as run's
        return f"haptic-bus {command}: error: {error.detail}"
    return f"haptic-bus {command}: error: {error}"


SHARED_CONTEXTS = frozenset({"run"})
"""Contexts of a check that several commands share (the run folder's ``--out``: run, demo, validate): their
line names the command typed, not the one the check was written for (``haptic-bus demo: error: run: --out
= ...`` named ``run``, which the user never typed)."""


def add_verbosity(parser: argparse.ArgumentParser, default: object) -> None:
    """``-v`` (repeatable) / ``-q``, mutually exclusive."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("-v", "--verbose", action="count", default=default, help="more log output (-vv: debug)")
    group.add_argument("-q", "--quiet", action="store_true", default=default, help="errors only, no live view")


def add_command(subparsers: argparse._SubParsersAction, name: str, help_text: str, handler: Handler) -> argparse.ArgumentParser:
    """A subcommand ``name`` with the shared help formatter and verbosity options; it sets ``handler``."""
    parser: argparse.ArgumentParser = subparsers.add_parser(name, help=help_text, description=help_text,
                                                            formatter_class=HelpFormatter)
    add_verbosity(parser, argparse.SUPPRESS)
    parser.set_defaults(handler=handler)
    return parser
