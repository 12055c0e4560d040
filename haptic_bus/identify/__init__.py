"""System identification of the haptic handle: bus-free excitation design, the exact-model fit, the velocity check.

``haptic-bus identify`` (:mod:`haptic_bus.app.identify_cli`) runs a :class:`Session` against a
drive, records the cycles (:class:`Recorder`) and hands the :class:`Record` to :func:`identify`:
``m``, ``b``, Coulomb friction and the loop delay fitted on the exact zero-order-hold model
(:mod:`~haptic_bus.identify.model`, :mod:`~haptic_bus.identify.fit`), which velocity 0x606C
reports (:mod:`~haptic_bus.identify.velocity_check`), and what the data can support
(:mod:`~haptic_bus.identify.assessment`).  Nothing here touches a bus.
"""

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from haptic_bus.identify.assessment import Finding
    from haptic_bus.identify.fit import Estimate, PlantFit, Refusal, fit_plant
    from haptic_bus.identify.model import Plant
    from haptic_bus.identify.probe import ProbeResult
    from haptic_bus.identify.record import Phases, Record, Recorder, Scale
    from haptic_bus.identify.result import Identification, identify
    from haptic_bus.identify.session import Plan, Session
    from haptic_bus.identify.velocity_check import VelocityCheck, check_velocity

_HOME = {  # each public name -> its module, imported on first use (the fit loads scipy: ~0.8 s)
    "Finding": "assessment", "Estimate": "fit", "Refusal": "fit", "PlantFit": "fit", "fit_plant": "fit",
    "Plant": "model", "ProbeResult": "probe", "Phases": "record", "Record": "record", "Recorder": "record",
    "Scale": "record", "Identification": "result", "identify": "result", "Plan": "session", "Session": "session",
    "VelocityCheck": "velocity_check", "check_velocity": "velocity_check",
}


def __getattr__(name: str) -> Any:
    """``haptic_bus.identify.X``: the public name from its module, imported now (PEP 562)."""
    if name not in _HOME:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_HOME[name]}"), name)


__all__ = [
    "Estimate",
    "Finding",
    "Identification",
    "Refusal",
    "Phases",
    "Plan",
    "Plant",
    "PlantFit",
    "ProbeResult",
    "Record",
    "Recorder",
    "Scale",
    "Session",
    "VelocityCheck",
    "check_velocity",
    "fit_plant",
    "identify",
]
