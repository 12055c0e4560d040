"""``haptic-bus identify --write-profile FILE``: a copy of the profile with the measured device.

The copy keeps the source's layout and comments (``tomlkit``); it changes only

* ``[device]``: ``mass`` (the estimate), ``friction`` (the lowest credible ``b``, ``max(0, b - 3
  sigma)``: the gate judges with it), ``friction_source`` (what was measured, when, and that the
  gate uses ``b - 3 sigma``), ``coulomb_friction`` where the source states one (the lowest credible
  ``f_c``: the gate judges the encoder's quantisation with it) and ``velocity`` (the model 0x606C matched, a window or filter with
  the longest time the data allow: :attr:`~haptic_bus.identify.velocity_check.VelocityCheck.credible`);
* ``[loop]``: ``delay`` (the largest credible delay in samples, ``D + 3 sigma``, in whole samples
  when the fraction was not resolved; never below the least delay of the profile's ``timing``:
  a ``cia402`` profile keeps at least 1 even if the drive closes the loop faster);
* ``[identification]``: the estimates with their standard errors, the date, the excitation's
  length and the residual (m); the loader refuses a ``[device]``/``[loop]`` more optimistic than
  it, so the gate's values are computed from exactly the numbers written there and rounded the
  safe way (friction down, delay up).

Each changed line gets a comment saying what its value is now (the old comment described the old
value).  A ``coulomb_friction`` the source does not state is not added (stating it makes the gate
judge quantisation, which refuses every spring of a ``point``, ``lowpass`` or ``window`` device:
:mod:`haptic_bus.analysis.quantisation`); ``velocity_noise`` never goes into ``[device]``.
"""

from __future__ import annotations

import datetime as dt
import decimal
import math
import pathlib
from typing import Any

import tomlkit
from tomlkit.items import Table

from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.app.whole_file import write_text_whole
from haptic_bus.errors import ParameterError
from haptic_bus.identify import Identification
from haptic_bus.profile.identification import CREDIBLE_SIGMAS, IdentifiedDevice

DIGITS = 6  # significant digits written


def _digits(value: float, rounding: str = decimal.ROUND_HALF_EVEN) -> float:
    """``value`` to :data:`DIGITS` significant digits, rounded as ``rounding`` says."""
    if value == 0.0 or not math.isfinite(value):
        return value
    exponent = math.floor(math.log10(abs(value))) - DIGITS + 1
    return float(decimal.Decimal(value).quantize(decimal.Decimal(1).scaleb(exponent), rounding=rounding))


def stamp(moment: dt.datetime) -> str:
    """``2026-11-30T22:50:00Z``: the UTC time of ``moment`` to the second."""
    return moment.astimezone(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _set(table: Table, key: str, value: Any, comment: str = "") -> None:
    """``key = value  # comment`` in ``table``, in place if the key is there: its old comment replaced
    (or dropped), the new one in the old one's column where the new value leaves room."""
    old = table.get(key)
    column = len(old.as_string()) + len(old.trivia.comment_ws) if old is not None and old.trivia.comment else None
    table[key] = value
    if comment:
        item = table[key]
        item.comment(comment)
        if column is not None:
            item.trivia.comment_ws = " " * max(1, column - len(item.as_string()))


def identified_profile(source: pathlib.Path, identification: Identification, least_delay: float,
                       moment: dt.datetime) -> str:
    """The text of ``source`` with the identified values written in (see the module docstring);
    ``least_delay``: the smallest ``[loop] delay`` the profile's timing allows, samples."""
    fit, velocity = identification.fit, identification.velocity
    if fit is None or velocity is None or not identification.supported:
        raise ParameterError("--write-profile", str(source), "an identification the data support (nothing was written)")
    when = stamp(moment)
    # [identification] as written (6 digits); the gate's values from exactly those numbers, rounded the safe way
    b, b_sigma = _digits(fit.friction.value), _digits(fit.friction.stderr)
    d, d_sigma = _digits(fit.delay.value), _digits(fit.delay.stderr)
    friction = _digits(max(0.0, b - CREDIBLE_SIGMAS * b_sigma), decimal.ROUND_FLOOR)
    high = d + CREDIBLE_SIGMAS * d_sigma if fit.fraction_resolved else float(math.ceil(fit.delay_high - 1e-9))
    delay = max(least_delay, _digits(high, decimal.ROUND_CEILING))
    document = tomlkit.parse(source.read_text())
    device, loop = document["device"], document["loop"]
    assert isinstance(device, Table) and isinstance(loop, Table)  # the profile loader has checked the tables
    _set(device, "mass", _digits(fit.mass.value), f"kg, identified {when}: +- {fit.mass.stderr:.2g} (1 sigma)")
    _set(device, "friction", friction, "N s/m: b - 3 sigma of the identified b, what the gate judges with")
    _set(device, "friction_source",
         f"identified {when}: b = {b:.6g} ± {b_sigma:.2g} N s/m (1 sigma); the gate uses b - 3 sigma")
    if "coulomb_friction" in device:
        f_c, f_c_sigma = _digits(fit.coulomb.value), _digits(fit.coulomb.stderr)
        coulomb = _digits(max(0.0, f_c - CREDIBLE_SIGMAS * f_c_sigma), decimal.ROUND_FLOOR)
        _set(device, "coulomb_friction", coulomb, "N: f_c - 3 sigma of the identified f_c, what the gate judges with")
    matched = "" if velocity.credible == velocity.best else f" (best fit {velocity.best}; the longest credible time)"
    _set(device, "velocity", velocity.credible, f"0x606C as measured {when}{matched}")
    why = ("D + 3 sigma" if fit.fraction_resolved else "whole samples: the fraction was not resolved") + (
        "" if delay > least_delay else f"; at least {least_delay:g} for the timing")
    _set(loop, "delay", delay, f"samples: the largest credible loop delay ({why})")
    table = tomlkit.table()
    table.comment("written by haptic-bus identify; descriptive (the gate uses [device] and [loop])")
    measured = IdentifiedDevice(
        when, fit.mass.value, fit.mass.stderr, b, b_sigma, fit.coulomb.value, fit.coulomb.stderr, d, d_sigma,
        VelocityModel.parse(velocity.credible), identification.record.excitation_seconds,
        fit.residual_rms * identification.record.scale.position)
    for key, value in measured.as_table().items():
        table[key] = _digits(value) if isinstance(value, float) else value
    table["residual_rms"].comment("m: the fit's residual, in position")
    document["identification"] = table
    return tomlkit.dumps(document)


def write_identified_profile(source: pathlib.Path, destination: pathlib.Path, identification: Identification,
                             least_delay: float = 0.0, moment: dt.datetime | None = None, *,
                             replace: bool = False) -> pathlib.Path:
    """Write :func:`identified_profile` of ``source`` to ``destination``; the path written.  A file
    already there is replaced only with ``replace``: else the file is created only if none is there
    at that moment (an exclusive create), and one that appeared after the command checked, while it
    measured, raises FileExistsError and is left as it is; a write that fails leaves nothing there
    (:func:`~haptic_bus.app.whole_file.write_text_whole`)."""
    text = identified_profile(source, identification, least_delay, moment or dt.datetime.now(dt.UTC))
    return write_text_whole(destination, text, replace=replace)
