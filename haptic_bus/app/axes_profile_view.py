"""``haptic-bus profiles show|check`` of a multi-axis profile (``[[axes]]``): its axes, its scene in
space and the coupled gate's decision (:mod:`haptic_bus.app.axes_profile`), as text or JSON.

``check`` exits 0 when the coupled gate accepts every wall (passive with the profile's safety
margin), 1 when it does not; an invalid profile is a ParameterError (exit 2) before any of this.
"""

from __future__ import annotations

from typing import Any

from haptic_bus.app.axes_profile import AxesProfile
from haptic_bus.control.space_gate import SpaceDecision
from haptic_bus.control.space_scene import space_object_to_dict


def decision_to_dict(decision: SpaceDecision) -> dict[str, Any]:
    """The coupled gate's decision: accepted, the least margin (N s/m), reasons, every wall's margin."""
    return {"accepted": decision.accepted, "worst_margin": decision.worst_margin, "reasons": list(decision.reasons),
            "walls": [{"objects": list(w.objects), "margin": w.verdict.margin,
                       "critical_theta": w.verdict.critical_theta} for w in decision.walls]}


def axes_profile_to_dict(profile: AxesProfile, decision: SpaceDecision) -> dict[str, Any]:
    """A JSON-ready view of a multi-axis profile and its gate decision (SI units, as in the TOML)."""
    return {
        "profile": {"name": profile.name, "operator": profile.operator, "task": profile.task,
                    "description": profile.description},
        "path": None if profile.path is None else str(profile.path),
        "loop": {"period": profile.period}, "bus": {"bitrate": profile.bitrate},
        "gate": {"safety_margin": profile.gate_policy.safety_margin, "bandwidth": profile.gate_policy.bandwidth},
        "axes": [{"name": a.name, "node_id": a.node_id, "unit_id": a.unit_id, "timing": a.timing, "delay": a.delay,
                  "mapping": a.mapping, "force_limit": a.force_limit, "mass": a.device.mass,
                  "friction": a.device.friction, "velocity": str(a.device.velocity)} for a in profile.axes],
        "space": {"objects": [space_object_to_dict(o) for o in profile.space]},
        "gate_decision": decision_to_dict(decision),
    }


def _format_value(value: object) -> str:
    if isinstance(value, (list, tuple)):
        return "(" + ", ".join(f"{v:g}" for v in value) + ")"
    return f"{value:g}" if isinstance(value, float) else str(value)


def format_axes_profile(profile: AxesProfile, decision: SpaceDecision) -> str:
    """The text ``profiles show`` prints: who and what, every axis, the scene in space, the gate's decision."""
    lines = [f"profile {profile.name}  ({profile.path})", f"  operator: {profile.operator}", f"  task: {profile.task}",
             f"  description: {profile.description}",
             f"loop: T={profile.period:g} s, one SYNC for {len(profile.axes)} axes; bus {profile.bitrate:g} bit/s",
             f"gate: safety margin {profile.gate_policy.safety_margin:g} N s/m (coupled criterion)", "axes:"]
    for a in profile.axes:
        address = f"node {a.node_id}" if a.node_id is not None else f"unit {a.unit_id}"
        lines.append(f"  {a.name} ({address}): m={a.device.mass:g} kg b={a.device.friction:g} N s/m, timing {a.timing} "
                     f"(delay {a.delay:g} samples), velocity {a.device.velocity}, mapping {a.mapping}, "
                     f"force limit {a.force_limit:g} N")
    lines.append("scene in space:")
    for obj in profile.space:
        fields = space_object_to_dict(obj)
        kind, name = fields.pop("kind"), fields.pop("name")
        lines.append(f"  {kind} {name}: " + ", ".join(f"{k}={_format_value(v)}" for k, v in fields.items()))
    lines.append(f"coupled gate: {'accepts' if decision.accepted else 'REFUSES'}")
    lines += [f"  {'+'.join(w.objects)}: margin {w.verdict.margin:+.4g} N s/m at theta={w.verdict.critical_theta:.3g} rad"
              for w in decision.walls]
    lines += [f"  refused: {r}" for r in decision.reasons]
    return "\n".join(lines)
