"""``haptic-bus profiles show|check``'s view of a profile, either kind, as text or JSON: a one-axis
profile (device, loop, scene, operator model and the gate's decision, :mod:`haptic_bus.app.profiles.one_axis`)
and a multi-axis profile (``[[axes]]``: its axes, its scene in space and the coupled gate's decision,
:mod:`haptic_bus.app.profiles.axes`).  SI units, as in the TOML.
"""

from __future__ import annotations

from typing import Any

from haptic_bus.app.profiles import AxesProfile, Profile
from haptic_bus.control.gate import GateDecision
from haptic_bus.control.scene import object_to_dict
from haptic_bus.control.space_gate import SpaceDecision
from haptic_bus.control.space_scene import space_object_to_dict


def gate_decision_to_dict(decision: GateDecision) -> dict[str, Any]:
    """The 1-D gate's decision: accepted, the least margin (N s/m), reasons, warnings."""
    return {"accepted": decision.accepted, "worst_margin": decision.worst_margin,
            "reasons": list(decision.reasons), "warnings": list(decision.warnings)}


def format_profile(profile: Profile, decision: GateDecision) -> str:
    """The text ``profiles show`` prints of a one-axis profile: who and what, the device, the loop, the
    scene, the operator model, the gate's decision on every summed wall."""
    d, loop, gate = profile.device, profile.loop, profile.gate_policy
    lines = [
        f"profile {profile.name}  ({profile.path})",
        f"  operator: {profile.operator}",
        f"  task: {profile.task}",
        f"  description: {profile.description}",
        f"device: m={d.mass:g} kg  b={d.friction:g} N s/m (effective)",
        f"  friction source: {d.friction_source}",
        f"  scaling: {d.velocity_per_count:g} m/s per 0x606C unit, {d.position_per_count:g} m per 0x6064 increment,"
        f" 0x6076 = {d.rated_torque:g} N m, {d.force_per_torque:g} N/(N m), 0x6072 = {d.max_torque_permille}"
        f" per mille -> {d.max_force:g} N",
        f"loop: T={loop.period:g} s  timing {loop.timing} (delay {loop.delay:g} samples)  velocity {d.velocity}",
        f"force limit: {profile.force_limit:g} N",
        f"gate: safety margin {gate.safety_margin:g} N s/m, bandwidth rule {gate.bandwidth}",
        "scene:",
    ]
    for obj in profile.scene:
        fields = object_to_dict(obj)
        kind, name = fields.pop("kind"), fields.pop("name")
        lines.append(f"  {kind} {name}: " + ", ".join(f"{k}={v:g}" for k, v in fields.items()))
    lines.append("operator model: " + ", ".join(f"{k}={v}" for k, v in profile.operator_model.items()))
    lines.append(verdict_line("gate", profile, decision.accepted))
    for wall in decision.walls:
        lines.append(f"  {'+'.join(wall.objects)}: K={wall.K:g} N/m B={wall.B:g} N s/m margin "
                     f"{wall.verdict.margin:+.4g} N s/m at theta={wall.verdict.critical_theta:.3g} rad, alpha={wall.alpha:.3g}")
    lines += [f"  warning: {w}" for w in decision.warnings] + [f"  refused: {r}" for r in decision.reasons]
    return "\n".join(lines)


def verdict_line(gate: str, profile: Profile | AxesProfile, accepted: bool) -> str:
    """The view's line with the ``gate``'s verdict, one wording for either kind of profile (a refused
    scene the profile runs beyond the gate says so)."""
    if accepted:
        return f"{gate}: accepts"
    beyond = " (the profile runs beyond it under the bound layer: [passivity] beyond_gate = true)"
    return f"{gate}: REFUSES" + (beyond if profile.passivity.beyond_gate else "")


def space_decision_to_dict(decision: SpaceDecision) -> dict[str, Any]:
    """The coupled gate's decision: accepted, the least margin (N s/m), reasons, warnings (the keys of
    :func:`gate_decision_to_dict`), every wall judged
    (:meth:`~haptic_bus.control.space_gate.SpaceDecision.wall_dicts`)."""
    return {"accepted": decision.accepted, "worst_margin": decision.worst_margin, "reasons": list(decision.reasons),
            "warnings": list(decision.warnings), "walls": decision.wall_dicts()}


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
    lines.append(verdict_line("coupled gate", profile, decision.accepted))
    lines += [f"  {'+'.join(w.objects)}: margin {w.verdict.margin:+.4g} N s/m at theta={w.verdict.critical_theta:.3g} rad"
              for w in decision.walls]
    lines += [f"  refused: {r}" for r in decision.reasons]
    return "\n".join(lines)
