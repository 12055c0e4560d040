"""``[identification]``: what ``haptic-bus identify`` measured, written into a profile and read back.

:class:`IdentifiedDevice` is the table's one definition: ``haptic-bus identify --write-profile``
writes it (:meth:`IdentifiedDevice.as_table`), the loader reads it (:func:`read_identification`)
and refuses a ``[device]``/``[loop]`` more optimistic than it (:func:`check_against_identification`).
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass, fields

from haptic_bus.analysis.loop import DELAY_RANGE, FRICTION_RANGE, MASS_RANGE
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.profile.device import DeviceTable, LoopTiming
from haptic_bus.profile.reader import Reader, profile_error

CREDIBLE_SIGMAS = 3.0
"""Identified values: the gate judges at the estimate -/+ this many standard errors."""
_ESTIMATES = (("mass", MASS_RANGE[1], "kg"), ("friction", FRICTION_RANGE[1], "N s/m"),
              ("coulomb_friction", 1e6, "N"), ("delay", DELAY_RANGE[1], "samples"))


@dataclass(frozen=True)
class IdentifiedDevice:
    """``[identification]``: what ``haptic-bus identify`` measured on ``date`` (ISO 8601 text).
    Estimates with standard errors: ``mass`` kg, ``friction`` N s/m, ``coulomb_friction`` N,
    ``delay`` samples; ``velocity`` the model 0x606C matched; ``excitation_s`` s;
    ``residual_rms`` the fit's residual (m, position)."""

    date: str
    mass: float
    mass_stderr: float
    friction: float
    friction_stderr: float
    coulomb_friction: float
    coulomb_friction_stderr: float
    delay: float
    delay_stderr: float
    velocity: VelocityModel
    excitation_s: float
    residual_rms: float

    @property
    def lowest_credible_friction(self) -> float:
        """``max(0, b - 3 stderr)`` N s/m: the friction the gate may judge with, at most."""
        return max(0.0, self.friction - CREDIBLE_SIGMAS * self.friction_stderr)

    @property
    def largest_credible_delay(self) -> float:
        """``D + 3 stderr`` samples: the loop delay the gate must judge with, at least."""
        return self.delay + CREDIBLE_SIGMAS * self.delay_stderr

    def as_table(self) -> dict[str, str | float]:
        """The ``[identification]`` table as TOML writes it (the velocity model as its profile string)."""
        return {f.name: str(value) if isinstance(value := getattr(self, f.name), VelocityModel) else value
                for f in fields(self)}


def read_identification(path: pathlib.Path, table: object) -> IdentifiedDevice | None:
    """``[identification]`` (optional, ``table`` None when absent): see :class:`IdentifiedDevice`."""
    if table is None:
        return None
    r = Reader(path, "identification", table)
    date = r.text("date")
    values = {name: r.real(name, 0.0, high, unit) for key, high, unit in _ESTIMATES for name in (key, f"{key}_stderr")}
    model = r.velocity_model("velocity")
    excitation = r.real("excitation_s", 0.0, 1e7, "s")
    residual = r.real("residual_rms", 0.0, 1e6, "m")
    r.done()
    return IdentifiedDevice(date, velocity=model, excitation_s=excitation, residual_rms=residual, **values)


def check_against_identification(path: pathlib.Path, device: DeviceTable, loop: LoopTiming,
                                 measured: IdentifiedDevice) -> None:
    """Refuse a ``[device]``/``[loop]`` more optimistic than what was measured: another velocity
    model (or a shorter window or filter), friction or Coulomb friction above the lowest credible, delay below the
    largest credible (:data:`CREDIBLE_SIGMAS` standard errors)."""
    declared, found = device.velocity, measured.velocity
    if declared.kind != found.kind or declared.time < found.time * (1.0 - 1e-9):
        raise profile_error(path, "device.velocity", str(declared),
                            f"the model identification measured on {measured.date}: {found} (or a longer window or filter)")
    if device.friction > measured.lowest_credible_friction * (1.0 + 1e-9):
        raise profile_error(path, "device.friction", device.friction,
                            f"at most {measured.lowest_credible_friction:.6g} N s/m, the lowest credible value measured on "
                            f"{measured.date} (b = {measured.friction:.6g} ± {measured.friction_stderr:.2g} N s/m)")
    credible_coulomb = max(0.0, measured.coulomb_friction - CREDIBLE_SIGMAS * measured.coulomb_friction_stderr)
    if device.coulomb_friction is not None and device.coulomb_friction > credible_coulomb * (1.0 + 1e-9):
        raise profile_error(path, "device.coulomb_friction", device.coulomb_friction,
                            f"at most {credible_coulomb:.6g} N, the lowest credible value measured on {measured.date} "
                            f"(f_c = {measured.coulomb_friction:.6g} ± {measured.coulomb_friction_stderr:.2g} N)")
    if loop.delay < measured.largest_credible_delay - 1e-9:
        raise profile_error(path, "loop.delay", loop.delay,
                            f"at least {measured.largest_credible_delay:.6g} samples, the largest credible delay measured "
                            f"on {measured.date} (D = {measured.delay:.6g} ± {measured.delay_stderr:.2g} samples)")
