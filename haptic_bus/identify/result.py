"""An identification, whole: the run's record, the probe, the fit, the velocity check and the findings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.errors import Refusal
from haptic_bus.identify.assessment import Finding, assess
from haptic_bus.identify.bounds import MAX_DELAY
from haptic_bus.identify.fit import Estimate, PlantFit, fit_plant
from haptic_bus.identify.probe import ProbeResult
from haptic_bus.identify.record import Record
from haptic_bus.identify.velocity_check import VelocityCheck, check_velocity


@dataclass(frozen=True)
class Identification:
    """What one run found.  ``fit`` and ``velocity`` are None when the probe refused the handle or no
    fit was possible; ``findings`` say what the data can and cannot support."""

    record: Record
    probe: ProbeResult
    fit: PlantFit | None
    velocity: VelocityCheck | None
    findings: tuple[Finding, ...]

    @property
    def supported(self) -> bool:
        """The probe found the handle free, a fit exists and no finding blocks ``m`` or ``b``."""
        return self.probe.free and self.fit is not None and not any(f.blocks for f in self.findings)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready view (SI units; distances in 0x606C units, residuals in 0x6064 increments)."""
        record = self.record
        out: dict[str, Any] = {
            "supported": self.supported,
            "probe": {"free": self.probe.free, "message": self.probe.message, "force": self.probe.force,
                      "excursions": list(self.probe.excursions)},
            "run": {"period": record.period, "cycles": record.cycles, "seconds": record.seconds,
                    "excitation_s": record.excitation_seconds, "saturated_cycles": record.saturated,
                    "force_limit": record.force_limit},
            "fit": None if self.fit is None else _fit_dict(self.fit),
            "velocity": None if self.velocity is None else _velocity_dict(self.velocity),
            "findings": [{"topic": f.topic, "severity": f.severity, "message": f.message} for f in self.findings],
        }
        return out


def _estimate(estimate: Estimate) -> dict[str, Any]:
    return {"value": estimate.value, "stderr": estimate.stderr, "interval95": list(estimate.interval())}


def _fit_dict(fit: PlantFit) -> dict[str, Any]:
    return {
        "mass": _estimate(fit.mass), "friction": _estimate(fit.friction), "coulomb_friction": _estimate(fit.coulomb),
        "delay": _estimate(fit.delay) | {"whole": fit.whole_delay, "fraction_resolved": fit.fraction_resolved},
        "gate": {"friction_low": fit.friction_low, "delay_high": fit.delay_high},
        "residual": {"rms": fit.residual_rms, "quantization_rms": fit.quantization_rms,
                     "correlation": fit.residual_correlation, "correlation_bound": fit.correlation_bound,
                     "equations": fit.equations, "directions": list(fit.directions)},
        "quantization_compensation": fit.compensation,
        "whole_delay_rms": list(fit.delays),
    }


def _velocity_dict(velocity: VelocityCheck) -> dict[str, Any]:
    declared = velocity.declared
    return {
        "best": velocity.best, "credible": velocity.credible, "consistent": list(velocity.consistent),
        "samples": velocity.samples,
        "distances": [{"model": d.model, "rms": d.rms, "bic": d.bic, "credible": d.credible} for d in velocity.distances],
        "declared": None if declared is None else {"model": declared.model, "rms": declared.rms, "bic": declared.bic},
        "matches_declared": velocity.matches_declared,
    }


def identify(record: Record, probe: ProbeResult, left_envelope: bool = False,
             declared: VelocityModel | str | None = None, max_delay: int = MAX_DELAY) -> Identification:
    """Fit, check the velocity model and assess one run's ``record`` (``probe``: the run's probe;
    ``declared``: the velocity model the profile states, if any)."""
    if not probe.free:
        return Identification(record, probe, None, None, ())
    try:
        fit = fit_plant(record, max_delay)
    except Refusal as error:
        return Identification(record, probe, None, None, (Finding("travel", "cannot support", str(error)),))
    velocity = check_velocity(record, fit.plant, declared)
    return Identification(record, probe, fit, velocity, assess(record, fit, velocity, left_envelope, max_delay))
