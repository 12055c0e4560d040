"""The commented profile ``haptic-bus profiles new`` writes, and what such a file still lacks.

A new profile holds what is known and asks for the rest.  Known: what the drive states
(:class:`~haptic_bus.app.drive_statement.DriveStatement`: 0x6076, 0x6072 and the factor group,
each value with the object it came from), what the command line gave (first guesses of ``mass``,
``friction``, ``velocity``, and the ``force_limit``), and defaults that are the user's choice
rather than a property of the handle (period 1 ms, cia402 timing, the gate's policy).  Asked:
every other value a run needs (:data:`ASKS`: the handle's mass and friction, the velocity model
of 0x606C, the drive's scaling where it states none, the force limit, the scene's objects), each
as a commented line ``# key = ?  # ASKED: unit, allowed range; what it is`` with the ranges the
profile loader enforces (:mod:`haptic_bus.app.profiles`).  The optional loop ``delay`` is a
commented line too, with its default.

:func:`missing` reads a TOML document and lists the asks it still lacks, so ``haptic-bus profiles
check FILE`` says exactly what is missing instead of the loader's first complaint.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import tomlkit

from drives.base import SCALING_UNITS, ScalingReading
from haptic_bus.analysis.loop import FRICTION_RANGE, MASS_RANGE
from haptic_bus.analysis.velocity import ALLOWED as VELOCITY_MODELS
from haptic_bus.app.drive_statement import DriveStatement
from haptic_bus.app.profiles import FORCE_RANGE
from haptic_bus.profile.device import PERMILLE_RANGE, RATED_TORQUE_RANGE, SCALE_RANGE
from haptic_bus.validation import real_range

DEFAULT_PERIOD = 0.001  # s
DEFAULT_TIMING = "cia402"


@dataclass(frozen=True)
class Ask:
    """One value a new profile asks for: its dotted ``key``, ``unit`` and range as the loader has them, and ``why``."""

    key: str
    allowed: str
    why: str

    @property
    def table(self) -> str:
        return self.key.split(".")[0]

    @property
    def name(self) -> str:
        return self.key.split(".", 1)[1]


def _real(low: float, high: float, unit: str, low_open: bool = False) -> str:
    return f"{unit}, {real_range(low, high, low_inclusive=not low_open)}"


SCALING_ASKS = {
    "velocity_per_count": Ask("device.velocity_per_count", _real(*SCALE_RANGE, "m/s per 0x606C unit", True),
                              "the handle's speed per unit of 0x606C (the drive's 0x60A9 and factor group, or its manual)"),
    "position_per_count": Ask("device.position_per_count", _real(*SCALE_RANGE, "m per 0x6064 increment", True),
                              "the handle's travel per 0x6064 increment (encoder resolution and transmission)"),
    "rated_torque": Ask("device.rated_torque", _real(*RATED_TORQUE_RANGE, "N m (0x6076), a whole number of mN m"),
                        "the motor's rated torque, 0x6076"),
    "force_per_torque": Ask("device.force_per_torque", _real(*SCALE_RANGE, "N/(N m)", True),
                            "the transmission: handle force per motor torque, 2 pi / (metres per motor revolution)"),
    "max_torque_permille": Ask("device.max_torque_permille", f"an integer in [{PERMILLE_RANGE[0]}, {PERMILLE_RANGE[1]}]",
                               "0x6072, the largest torque the drive applies, per mille of 0x6076"),
}
MASS = Ask("device.mass", _real(*MASS_RANGE, "kg"),
           "the moving mass at the handle (handle, carriage, reflected rotor inertia); a first guess within 4x is enough "
           "for `haptic-bus identify`, which measures it")
FRICTION = Ask("device.friction", _real(*FRICTION_RANGE, "N s/m"),
               "the effective viscous friction b; a first guess for `haptic-bus identify`, which measures it and writes "
               "the lowest credible value")
VELOCITY = Ask("device.velocity", VELOCITY_MODELS,
               "what the drive's 0x606C is (its manual; most servo drives report 'average', an encoder difference over "
               "the cycle); `haptic-bus identify` says which the data match and writes it")
SCENE = Ask("scene.objects", "at least one [[scene.objects]] table (kind wall, slot or detent)",
            "the virtual objects to render; `haptic-bus check --mass M --friction b --period T --delay D` says which "
            "K and B the identified handle allows")


def force_limit_ask(max_force: float | None) -> Ask:
    """The force limit, bounded by what 0x6072 allows when the scaling is known."""
    high = FORCE_RANGE[1] if max_force is None else max_force
    where = "" if max_force is None else " (what 0x6072 allows at the handle)"
    return Ask("limits.force_limit", _real(FORCE_RANGE[0], high, "N", True) + where,
               "the most force identify and the walls may ask; keep it below what the handle and the hand can bear")


ASKS = (MASS, FRICTION, VELOCITY, *SCALING_ASKS.values(), force_limit_ask(None), SCENE)
"""Every value a new profile may ask for (a file lacks one: :func:`missing` lists it)."""


def _value(value: Any) -> str:
    return tomlkit.item(value).as_string()


def _line(key: str, value: Any, comment: str) -> str:
    return f"{f'{key} = {_value(value)}':<32} # {comment}"


def _asked(ask: Ask) -> str:
    return f"{f'# {ask.name} = ?':<32} # ASKED: {ask.allowed}; {ask.why}"


def _stated(field: str, reading: ScalingReading) -> str:
    detail = f" ({reading.detail})" if reading.detail else ""
    return _line(field, reading.value, f"{SCALING_UNITS[field]}: stated by the drive, {reading.source}{detail}")


def max_force(scaling: Mapping[str, Any]) -> float | None:
    """N at the handle that 0x6072 allows, if the three factors are known (values or readings)."""
    values = {k: getattr(v, "value", v) for k, v in scaling.items()}
    if not {"max_torque_permille", "rated_torque", "force_per_torque"} <= set(values):
        return None
    return float(values["max_torque_permille"] * values["rated_torque"] * values["force_per_torque"] / 1000.0)


def template(name: str, statement: DriveStatement | None, given: Mapping[str, Any], command: str,
             moment: dt.datetime) -> str:
    """The text of a new profile ``name``: ``statement`` (None: every drive value asked), ``given``
    (``mass``, ``friction``, ``velocity``, ``force_limit`` from the command line), ``command`` as typed."""
    stated = {} if statement is None else statement.scaling
    when = moment.astimezone(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    origin = (f"from {statement.source}: the values marked 'stated by the drive'" if statement is not None
              else "without a drive: every value the drive states is asked for")
    lines = [
        f"# Profile {name}, written by `{command}` on {when},",
        f"# {origin}.",
        "# A line '# key = ?  # ASKED: ...' asks for a value: replace it with 'key = VALUE' in the unit and range it",
        "# gives.  `haptic-bus profiles check FILE` lists what is still missing; `haptic-bus identify --profile FILE",
        "# --write-profile NEW` measures mass, friction, the velocity model and the loop delay from first guesses.",
        *(f"# note: {note}" for note in (statement.notes if statement is not None else ())),
        "",
        "[profile]",
        _line("name", name, "letters, digits, '.', '_', '-'"),
        _line("operator", "commissioning engineer", "who uses this profile"),
        _line("task", "commission the axis: identify the handle, then render the walls", "what for"),
        _line("description", f"written by haptic-bus profiles new on {when}", "anything that helps the next reader"),
        "",
        "[device]",
        _line("mass", given["mass"], "kg: a first guess (profiles new --mass); identify measures it")
        if "mass" in given else _asked(MASS),
        _line("friction", given["friction"], "N s/m: a first guess (profiles new --friction); identify measures it")
        if "friction" in given else _asked(FRICTION),
        _line("friction_source", "not measured yet: haptic-bus identify --write-profile writes it", "where b comes from"),
        _line("velocity", given["velocity"], "0x606C's model as given (profiles new --velocity); identify checks it")
        if "velocity" in given else _asked(VELOCITY),
        *(_stated(field, stated[field]) if field in stated else _asked(ask) for field, ask in SCALING_ASKS.items()),
        "",
        "[loop]",
        _line("period", DEFAULT_PERIOD, "s: the SYNC period the controller runs (0x1006 is written from it)"),
        _line("timing", DEFAULT_TIMING, "a CiA-402 drive in cyclic synchronous torque applies a torque at the next SYNC"),
        f"{'# delay = 1':<32} # optional: samples, the loop delay the gate judges with (1 for cia402 timing); "
        "identify writes the largest credible one",
        "",
        "[limits]",
    ]
    limit = max_force(stated)
    lines.append(_line("force_limit", given["force_limit"], "N (profiles new --force-limit)" + (
        "" if limit is None else f"; at most {limit:g} N, what 0x6072 allows")) if "force_limit" in given
        else _asked(force_limit_ask(limit)))
    lines += [
        "",
        "[gate]",
        _line("safety_margin", 0.0, "N s/m the gate asks beyond passivity: raise it to guard against a b lower than measured"),
        _line("bandwidth", "warn", "'warn' or 'strict': the alpha = B/(K T) > 6 rule"),
        "",
        "[scene]",
        f"# ASKED: {SCENE.allowed}; {SCENE.why}.  For example a wall 3 mm ahead of the start, solid beyond it:",
        "# [[scene.objects]]",
        '# kind = "wall"                  # wall | slot | detent',
        '# name = "end-stop"',
        "# position = 0.003               # m",
        "# normal = -1                    # -1: solid for x > position (pushed into in +x); +1: solid below",
        "# stiffness = 500.0              # N/m",
        "# damping = 5.0                  # N s/m",
        "",
    ]
    return "\n".join(lines)


def missing(document: Mapping[str, Any]) -> list[Ask]:
    """The asks of :data:`ASKS` that ``document`` (a parsed TOML profile) still lacks, in order (the
    force limit's range from the document's own scaling where it has it)."""
    device = document.get("device")
    limit = max_force({k: v for k, v in device.items() if isinstance(v, (int, float))}) if isinstance(device, Mapping) else None
    lacking = []
    for ask in ASKS:
        if ask.key == "limits.force_limit":
            ask = force_limit_ask(limit)
        table = document.get(ask.table)
        value = table.get(ask.name) if isinstance(table, Mapping) else None
        if value is None or (ask is SCENE and not value):
            lacking.append(ask)
    return lacking
