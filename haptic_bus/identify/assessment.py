"""Can the data support the estimates?  The findings an identification reports beside its numbers.

A finding that ``blocks`` means the data cannot support ``m`` or ``b`` (the values the passivity
gate uses): the command exits 1 and writes no profile.  The others are warnings (the estimate
stands, with a caveat) and notes.  Thresholds, and why:

* **travel**: the usable cycles must move :data:`MIN_STEP_INCREMENTS` increments rms (rounding
  is then below 3 % of each step);
* **saturation**: at most :data:`MAX_SATURATED` of the cycles clipped at the force limit (the
  fit uses the clipped force, so it is not biased, but a loop that keeps hitting the limit did
  not get the excitation it was designed for);
* **sticking**: at least :data:`MIN_USABLE` of the excitation's cycles usable (free of reversal
  and sticking) -- fewer, and Coulomb friction dominates the force that was available;
* **noise**: ``3 sigma`` of ``m`` and of ``b`` within :data:`MAX_RELATIVE` of the value;
* **resolution**: the quantisation compensation moved ``b`` by at most :data:`MAX_COMPENSATION`
  of it (beyond, the rounding of the encoder is no longer a small noise, and its model is
  stretched);
* warnings: residuals more than :data:`RESIDUAL_FACTOR` times what rounding explains, or
  correlated beyond the rounding's reach (the model misses something; the standard errors
  carry it, the sandwich estimate being robust to it); cycles without fresh inputs (left out);
  Coulomb friction seen in one direction only (it is then a constant force, not friction); the
  excursion guard ended the excitation; 0x606C contradicting the declared velocity model; notes:
  an unresolved fraction of a sample, several velocity models indistinguishable at the drive's
  noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic_bus.identify.bounds import MAX_DELAY
from haptic_bus.identify.fit import PlantFit
from haptic_bus.identify.model import usable_equations
from haptic_bus.identify.record import Record
from haptic_bus.identify.velocity_check import VelocityCheck

MIN_STEP_INCREMENTS = 10.0
MAX_SATURATED = 0.05
MIN_USABLE = 0.3
MAX_RELATIVE = 0.10
MAX_COMPENSATION = 0.3
RESIDUAL_FACTOR = 3.0
MIN_DIRECTION = 0.1  # of the usable cycles, each way, for Coulomb friction to be friction


@dataclass(frozen=True)
class Finding:
    """``topic`` (travel, saturation, ...), whether it ``blocks`` the estimate, a ``severity``
    ("cannot support", "warning", "note") and the one-line ``message``."""

    topic: str
    severity: str
    message: str

    @property
    def blocks(self) -> bool:
        """The data cannot support ``m`` or ``b``."""
        return self.severity == "cannot support"


def _blocking(topic: str, message: str) -> Finding:
    return Finding(topic, "cannot support", message)


def _warning(topic: str, message: str) -> Finding:
    return Finding(topic, "warning", message)


def assess(record: Record, fit: PlantFit, velocity: VelocityCheck, left_envelope: bool,
           max_delay: int = MAX_DELAY) -> tuple[Finding, ...]:
    """The findings on one identification (see the module docstring)."""
    return (*_data_findings(record, left_envelope), *_fit_findings(record, fit, max_delay), *_velocity_findings(velocity))


def _data_findings(record: Record, left_envelope: bool) -> list[Finding]:
    findings = []
    usable = usable_equations(record)
    steps = np.abs(np.diff(record.position_counts.astype(float)))[1:][usable]
    step_rms = float(np.sqrt(np.mean(steps**2))) if steps.size else 0.0
    if step_rms < MIN_STEP_INCREMENTS:
        findings.append(_blocking("travel", f"too little travel for the encoder: {step_rms:.3g} increments per cycle "
                                            f"(rms) where the handle moved, at least {MIN_STEP_INCREMENTS:g} needed; "
                                            "allow more --travel or a higher force limit"))
    share = record.saturated / max(1, record.cycles)
    if share > MAX_SATURATED:
        findings.append(_blocking("saturation", f"the command hit the force limit ({record.force_limit:.3g} N) in "
                                                f"{100 * share:.3g} % of the cycles (at most {100 * MAX_SATURATED:g} %)"))
    start, stop = record.phases.probe, record.phases.excitation
    excited = usable[max(0, start - 1) : max(0, stop - 1)]
    fraction = float(excited.mean()) if excited.size else 0.0
    if fraction < MIN_USABLE:
        findings.append(_blocking("sticking", f"the handle stuck or reversed in {100 * (1 - fraction):.3g} % of the "
                                              f"excitation's cycles (at most {100 * (1 - MIN_USABLE):g} %): friction takes "
                                              f"too much of the {record.force_limit:.3g} N force limit"))
    stale = int(np.count_nonzero(~record.fresh))
    if stale:
        findings.append(_warning("stale", f"{stale} cycle(s) without fresh inputs (a TPDO missed its timeout) or "
                                          "closing a period the machine stretched (a stall): the equations around "
                                          "them were left out"))
    if left_envelope:
        findings.append(_warning("envelope", f"the handle left the travel envelope after "
                                             f"{record.excitation_seconds:.3g} s; the excitation ended early"))
    return findings


def _fit_findings(record: Record, fit: PlantFit, max_delay: int) -> list[Finding]:
    findings = []
    for name, estimate, unit in (("mass", fit.mass, "kg"), ("friction", fit.friction, "N s/m")):
        if 3.0 * estimate.relative > MAX_RELATIVE:
            findings.append(_blocking("noise", f"the data cannot support {name} = {estimate.value:.4g} {unit}: 3 sigma = "
                                               f"{300 * estimate.relative:.3g} % of it (at most {100 * MAX_RELATIVE:g} %)"))
    b = fit.friction.value
    if b > 0 and abs(fit.compensation) > MAX_COMPENSATION * b:
        findings.append(_blocking("resolution", f"the encoder's rounding biases b by {fit.compensation:+.3g} N s/m "
                                                f"({100 * fit.compensation / b:+.3g} %) before compensation: too coarse "
                                                "for this travel"))
    if fit.residual_rms > RESIDUAL_FACTOR * fit.quantization_rms:
        findings.append(_warning("residual", f"residuals {fit.residual_rms:.3g} increments rms, "
                                             f"{fit.residual_rms / fit.quantization_rms:.3g} times what rounding explains: "
                                             "the model misses something (compliance, a hand, position-dependent friction)"))
    if fit.residual_correlation > fit.correlation_bound:
        findings.append(_warning("residual", f"residuals correlated beyond the rounding (|r| = "
                                             f"{fit.residual_correlation:.3g} > {fit.correlation_bound:.3g} at lags 3-20): "
                                             "unmodelled dynamics"))
    forward, backward = fit.directions
    if min(forward, backward) < MIN_DIRECTION * fit.equations:
        findings.append(_warning("coulomb", "Coulomb friction not excited: the handle moved clearly in one "
                                            "direction only, so Fc is indistinguishable from a constant force"))
    if fit.delay.value + 3.0 * fit.delay.stderr >= max_delay + 1:
        findings.append(_blocking("delay", f"the delay reaches the end of the searched range ({max_delay + 1} samples)"))
    elif not fit.fraction_resolved:
        findings.append(Finding("delay", "note", f"the fraction of the delay is not resolved "
                                                 f"(D = {fit.delay.value:.3g} +- {fit.delay.stderr:.2g} samples): "
                                                 f"whole samples only, pessimistic {fit.delay_high:g}"))
    return findings


def _velocity_findings(velocity: VelocityCheck) -> list[Finding]:
    findings = []
    if velocity.matches_declared is False and velocity.declared is not None:
        findings.append(_warning("velocity", f"0x606C contradicts the declared velocity model "
                                             f"{velocity.declared.model}: it matches {velocity.best}"))
    if len(velocity.consistent) > 1:
        findings.append(Finding("velocity", "note", "at this noise 0x606C cannot tell apart: "
                                                    + ", ".join(velocity.consistent)))
    return findings
