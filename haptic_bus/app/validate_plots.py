"""``haptic-bus validate``'s pictures, drawn into the run's folder.

* ``validate-bode.png``: the probe's response in velocity (m/s per N), measured (with its
  standard error, three of them as the band) against the model's prediction, magnitude and phase
  over frequency; the title says the verdict.
* ``validate-re-z.png``: the device's impedance at the handle's port as the model would have to be to
  produce what was measured, ``Z = (b + j omega m) P / H`` (N s/m; ``H`` the measured plant from
  force sent to reported velocity, ``P`` the model's exact sampled plant, so the sampling, the
  hold and the model's delay divide out), its real part: the effective friction, the model's ``b``
  wherever the model holds.  An extra lag ``tau`` shows as ``b - m omega^2 tau`` (DESIGN 3.5: a lag
  turns mass into negative damping), a transmission as its resonance.  Marked: the model's ``b``
  and ``b - margin``, the friction down to which the profile's scene stays passive (the gate's
  least margin); where the device's effective friction falls below that line, the gate's verdict
  on the profile's walls does not cover the device.  Symmetric-log axis: a departure spans decades.
"""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from haptic_bus.app.figure_file import save_figure
from haptic_bus.app.run_folder import BODE_PNG, RE_Z_PNG
from haptic_bus.validate.verdict import Validation

_DPI = 110  # each figure is made at the dpi it is saved at: tight_layout's text measures serve the save


def draw(validation: Validation, folder: pathlib.Path, margin: float | None) -> list[pathlib.Path]:
    """Both pictures in ``folder``; ``margin``: the profile's scene's least margin (N s/m), None without walls."""
    return [bode(validation, folder / BODE_PNG), re_z(validation, folder / RE_Z_PNG, margin)]


def bode(validation: Validation, path: pathlib.Path) -> pathlib.Path:
    """The measured and predicted velocity response (module docstring)."""
    f = validation.plan.frequencies
    measured, predicted = validation.velocity, validation.prediction.velocity
    fig, (gain, phase) = plt.subplots(2, 1, figsize=(8, 7), sharex=True, dpi=_DPI)
    band = 3.0 * measured.error
    gain.fill_between(f, np.abs(measured.mean) - band, np.abs(measured.mean) + band, color="tab:blue", alpha=0.25,
                      label="measured +- 3 standard errors")
    gain.loglog(f, np.abs(measured.mean), color="tab:blue", lw=1.2, label="measured")
    gain.loglog(f, np.abs(predicted), color="black", ls="--", lw=1.0, label="model (exact sampled loop)")
    gain.set_ylabel("|velocity / probe|, m/s per N")
    gain.legend(loc="lower left")
    gain.grid(True, which="both", alpha=0.3)
    phase.semilogx(f, np.degrees(np.unwrap(np.angle(measured.mean))), color="tab:blue", lw=1.2, label="measured")
    phase.semilogx(f, np.degrees(np.unwrap(np.angle(predicted))), color="black", ls="--", lw=1.0, label="model")
    phase.set_ylabel("phase, degrees")
    phase.set_xlabel("frequency, Hz")
    phase.grid(True, which="both", alpha=0.3)
    phase.legend(loc="lower left")
    fig.suptitle(_title(validation), fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, dpi=_DPI)


def re_z(validation: Validation, path: pathlib.Path, margin: float | None) -> pathlib.Path:
    """The device's effective friction against the gate's margin (module docstring)."""
    f = validation.plan.frequencies
    b = validation.loop.b
    plant, model = validation.plant, validation.prediction.plant
    rigid = b + 2j * np.pi * f * validation.loop.m
    effective = np.real(rigid * model / plant.mean)
    error = np.abs(rigid * model / plant.mean) * plant.error / np.abs(plant.mean)  # |dZ| = |Z| |dH| / |H|
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=_DPI)
    ax.fill_between(f, effective - 3.0 * error, effective + 3.0 * error, color="tab:blue", alpha=0.25,
                    label="measured +- 3 standard errors")
    ax.plot(f, effective, color="tab:blue", lw=1.2, label="device: Re[(b + j omega m) P / H]")
    ax.set_xscale("log")
    ax.set_yscale("symlog", linthresh=max(b, 1e-3))
    ax.axhline(b, color="black", ls="--", lw=1.0, label=f"model b = {b:g} N s/m")
    if margin is not None:
        ax.axhline(b - margin, color="tab:red", lw=1.2, label=f"b - gate margin = {b - margin:.3g} N s/m (walls passive above)")
    ax.set_xlabel("frequency, Hz")
    ax.set_ylabel("effective friction Re Z, N s/m")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(_title(validation), fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, dpi=_DPI)


def _title(validation: Validation) -> str:
    summary = validation.summary()
    return summary if len(summary) < 110 else summary[:107] + "..."
