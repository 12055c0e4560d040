"""Scenes in space in ``run.json``: each scene a multi-axis run had in effect, written
(:func:`space_scene_dict`, ``run.json``'s ``scenes``), and its objects read back for the trajectory's
picture (:func:`space_objects`).

A scene in space is written as its id, where it came from (``origin``: "profile", "upload",
"derate"), every object as its profile table (:func:`~haptic_bus.control.space_scene.space_object_to_dict`:
positions in m, K in N/m, B in N s/m) and the coupled gate's ``decision``: accepted, the least margin
(N s/m) and every wall judged (:meth:`~haptic_bus.control.space_gate.SpaceDecision.wall_dicts`).
"""

from __future__ import annotations

from typing import Any

from haptic_bus.control.scene_switch import SceneEntry
from haptic_bus.control.space_gate import SpaceDecision
from haptic_bus.control.space_scene import Box, Plane, SpaceObject, SpaceScene, Sphere


def space_scene_dict(entry: SceneEntry[SpaceScene, SpaceDecision]) -> dict[str, Any]:
    """One scene in space that was in effect (module docstring)."""
    decision = entry.decision
    return {"scene_id": entry.scene_id, "origin": entry.origin, "objects": entry.scene.object_dicts(),
            "decision": {"accepted": decision.accepted, "worst_margin": decision.worst_margin,
                         "walls": decision.wall_dicts()}}


def space_objects(document: dict[str, Any]) -> list[SpaceObject]:
    """The objects of the last scene ``run.json``'s ``document`` names (a run that never cycled: its
    profile's), as :func:`space_scene_dict` wrote them."""
    kinds = {cls.__name__.lower(): cls for cls in (Plane, Box, Sphere)}
    scenes = document.get("scenes") or [{"objects": document["settings"]["space"]["objects"]}]
    objects: list[SpaceObject] = []
    for entry in scenes[-1]["objects"]:
        fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in entry.items() if k != "kind"}
        objects.append(kinds[entry["kind"]](**fields))
    return objects
