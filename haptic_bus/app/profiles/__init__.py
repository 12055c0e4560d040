"""Operator parameter profiles, the controller's view: one loader for the two kinds of profile.

A TOML file without ``[[axes]]`` is a one-axis profile (:mod:`~haptic_bus.app.profiles.one_axis`,
:class:`Profile`: one handle, a scene on its line, the 1-D gate); one with ``[[axes]]`` is a
multi-axis profile (:mod:`~haptic_bus.app.profiles.axes`, :class:`AxesProfile`: one drive per
axis, a scene in space, the coupled gate, the CANopen bus load).  The file says which it is, so
there is one reader and one loader for both:

* :func:`read_profile` parses and validates either kind without judging its scene (ParameterError
  naming the file, the dotted field, the value and the allowed range);
* :func:`load_profile` reads and then judges the scene by the profile's own gate (:func:`admit`):
  a profile that loads is one its gate admits, or one that runs beyond the gate under the bound
  passivity layer (``[passivity] beyond_gate``);
* :func:`one_axis_only` is for the commands that measure one drive (identify, validate, report): it
  refuses a multi-axis profile in one line naming what they accept.
"""

from __future__ import annotations

import pathlib
from typing import Any, overload

from haptic_bus.app.profile_policies import NAME_PATTERN, StartPolicy
from haptic_bus.app.profiles.axes import AxesProfile, Axis, axes_to_dict, read_axes
from haptic_bus.app.profiles.one_axis import Profile, one_axis_to_dict, read_one_axis
from haptic_bus.control.gate import GateDecision
from haptic_bus.control.space_gate import SpaceDecision
from haptic_bus.errors import ParameterError, Refusal
from haptic_bus.profile.device import DeviceTable, LoopTiming
from haptic_bus.profile.files import DEFAULT_PROFILE, resolve_profile, shipped_profiles
from haptic_bus.profile.reader import read_document
from haptic_bus.profile.scene import FORCE_RANGE

__all__ = ["DEFAULT_PROFILE", "FORCE_RANGE", "NAME_PATTERN", "AxesProfile", "Axis", "DeviceTable", "LoopTiming",
           "Profile", "StartPolicy", "admit", "default_profile", "gate_refusal", "load_profile", "one_axis_only",
           "profile_to_dict", "read_profile", "resolve_profile", "shipped_profiles"]


def read_profile(path_or_name: str | pathlib.Path) -> Profile | AxesProfile:
    """Parse and validate a profile file (or shipped name) of either kind without judging its scene:
    a :class:`Profile`, or an :class:`AxesProfile` for a file with ``[[axes]]``; raise ParameterError."""
    path = resolve_profile(path_or_name)
    document = read_document(path)
    return read_axes(path, document) if "axes" in document else read_one_axis(path, document)


def profile_to_dict(profile: Profile | AxesProfile) -> dict[str, Any]:
    """A JSON-ready view of a profile of either kind, SI units (``run.json``'s ``settings``):
    :func:`~haptic_bus.app.profiles.one_axis.one_axis_to_dict` or :func:`~haptic_bus.app.profiles.axes.axes_to_dict`."""
    return axes_to_dict(profile) if isinstance(profile, AxesProfile) else one_axis_to_dict(profile)


@overload
def admit(profile: Profile) -> GateDecision: ...


@overload
def admit(profile: AxesProfile) -> SpaceDecision: ...


def admit(profile: Profile | AxesProfile) -> GateDecision | SpaceDecision:
    """The decision of the profile's gate (the coupled gate for several axes) on its scene; :class:`Refusal`
    if it refuses, unless the profile runs beyond the gate under the bound layer (``[passivity] beyond_gate``)."""
    decision = profile.judge()
    refusal = gate_refusal(profile, decision)
    if refusal is not None:
        raise refusal
    return decision


def gate_refusal(profile: Profile | AxesProfile, decision: GateDecision | SpaceDecision) -> Refusal | None:
    """The refusal that the gate's ``decision`` on ``profile``'s scene makes (None: accepted, or the
    profile runs beyond the gate under the bound layer)."""
    if decision.accepted or profile.passivity.beyond_gate:
        return None
    return Refusal.by_gate(decision, f"profile {profile.path or profile.name}", "scene")


def load_profile(path_or_name: str | pathlib.Path) -> Profile | AxesProfile:
    """Read, validate and gate a profile of either kind (:func:`read_profile`, then :func:`admit`);
    raise ParameterError (invalid, or a CANopen bus load above 70 %) or Refusal (not passive)."""
    profile = read_profile(path_or_name)
    admit(profile)
    return profile


def one_axis_only(profile: Profile | AxesProfile, command: str) -> Profile:
    """``profile`` if it is a one-axis profile; otherwise ParameterError (exit 2) saying that ``command``
    works on one axis and takes a profile without ``[[axes]]``."""
    if isinstance(profile, AxesProfile):
        raise ParameterError("profile", str(profile.path or profile.name), "a one-axis profile, without [[axes]] "
                             f"({command} works on one axis; this one has {len(profile.axes)} axes)")
    return profile


def default_profile() -> Profile | AxesProfile:
    """The shipped :data:`DEFAULT_PROFILE` (the one ``haptic-bus demo`` runs), loaded."""
    return load_profile(DEFAULT_PROFILE)
