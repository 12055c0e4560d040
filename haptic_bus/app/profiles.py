"""Operator parameter profiles: one TOML file = device, loop timing, scene, limits, gate policy.

A profile says who uses it for what (``[profile]``), the handle and its drive (``[device]``,
SI units, effective friction with its source, the ``velocity`` model of the drive's 0x606C),
the loop (``[loop]``: period in s, timing ``"ideal"`` = no delay, ``"cia402"`` = torque applied
at the next SYNC, ``"reception"`` = applied on arrival, and the loop ``delay`` in samples, real:
default 0 and 1 for the first two, required for the third), the force limit
(``[limits]``, N, at most what 0x6072 allows), the gate policy (``[gate]``), the virtual
objects (``[[scene.objects]]`` with ``kind`` = wall | slot | detent) and, for demos, the
simulated operator (``[operator_model]``, the table :func:`sim_drive.operator.operator_from_table`
takes: ``model`` = none | constant | step | sinusoid | chirp | hand | recorded (alias ``csv``)
plus that model's fields).  ``[identification]`` (optional) is what ``haptic-bus identify``
measured; a profile whose ``[device]`` or ``[loop]`` is more optimistic than its measurement
(velocity model, friction above the lowest credible value, delay below the largest) is refused.

:func:`load_profile` validates the whole file (unknown keys, types, ranges, names) and then
puts the compiled scene through the passivity gate, so a profile that loads is one the gate
admits.  Errors name the file, the dotted field (``scene.objects[2].stiffness``, 0-based
index), the value and the allowed range.
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import math
import pathlib
import re
import types
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from drives.base import DriveScaling
from drives.cia402 import MAX_TORQUE, MOTOR_RATED_TORQUE, TARGET_TORQUE
from drives.errors import ParameterError
from drives.safety import ABORT_OPTIONS, SafetySettings
from haptic_bus.analysis.loop import (
    DAMPING_RANGE,
    DELAY_RANGE,
    FRICTION_RANGE,
    MASS_RANGE,
    PERIOD_RANGE,
    STIFFNESS_RANGE,
    DeviceLoop,
)
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.app.profile_reader import REQUIRED, ProfileError, Reader, read_document
from haptic_bus.control.gate import BANDWIDTH_POLICIES, GateDecision, GatePolicy, GateRefusal, PassivityGate
from haptic_bus.control.passivity_layer import LAYER_MODES, LayerPolicy
from haptic_bus.control.scene import CompiledScene, Detent, SceneObject, Slot, Wall, compile_scene, object_to_dict
from haptic_bus.control.supervisor import Action, SupervisorPolicy

DEFAULT_PROFILE = "cia402-handle"
TIMINGS: dict[str, float | None] = {"ideal": 0, "cia402": 1, "reception": None}
"""Timing name -> its least loop delay in samples, the default of ``[loop] delay`` (None: required)."""
CREDIBLE_SIGMAS = 3.0
"""Identified values: the gate judges at the estimate -/+ this many standard errors."""
NOISE_SEED_RANGE = (0, 2**64 - 1)
SCALE_RANGE = (0.0, 1e6)  # exclusive low: m/s per count, m per count, N per N m
POSITION_RANGE = (-1e6, 1e6)  # m, as haptic_bus.control.scene
FORCE_RANGE = (0.0, 1e6)  # N, exclusive low
# 0x6072 is UNSIGNED16, but a torque beyond the INTEGER16 0x6071 can never be commanded.
PERMILLE_RANGE = (1, min(MAX_TORQUE.data_type.range[1], TARGET_TORQUE.data_type.range[1]))
RATED_TORQUE_RANGE = (1e-3, MOTOR_RATED_TORQUE.data_type.range[1] / 1000.0)  # N m (0x6076 in mN m)
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")  # a profile's name

# Operator models, aligned with sim_drive.operator (field -> (low, high, unit, default or
# REQUIRED)); haptic_bus does not import sim_drive (dependencies point the other way).
_F, _HZ, _T = (-1e6, 1e6, "N"), (0.0, 1e6, "Hz"), (0.0, 1e9, "s")
OPERATOR_FIELDS: dict[str, dict[str, tuple]] = {
    "none": {},
    "constant": {"level": (*_F, REQUIRED)},
    "step": {"level": (*_F, REQUIRED), "start": (*_T, REQUIRED)},
    "sinusoid": {"amplitude": (0.0, 1e6, "N", REQUIRED), "frequency": (*_HZ, REQUIRED),
                 "phase": (-2 * math.pi, 2 * math.pi, "rad", 0.0), "offset": (*_F, 0.0)},
    "chirp": {"amplitude": (0.0, 1e6, "N", REQUIRED), "f0": (*_HZ, REQUIRED), "f1": (*_HZ, REQUIRED),
              "duration": (0.0, 1e9, "s", REQUIRED)},
    "hand": {"stiffness": (0.0, 1e12, "N/m", REQUIRED), "damping": (0.0, 1e12, "N s/m", REQUIRED),
             "start": (-1e6, 1e6, "m", 0.0), "speed": (-1e6, 1e6, "m/s", 0.0),
             "amplitude": (0.0, 1e6, "m", 0.0), "frequency": (*_HZ, 0.0)},
    "recorded": {},  # path (CSV: time s, force N) and interpolation, checked apart
}
OPERATOR_ALIASES = {"csv": "recorded"}
INTERPOLATIONS = ("hold", "linear")


class ProfileRefusal(GateRefusal):
    """The passivity gate refused a profile's scene; ``path`` names the file."""

    def __init__(self, path: pathlib.Path | str, decision: GateDecision) -> None:
        super().__init__(decision)
        self.path = str(path)
        self.args = (f"profile {self.path}: {self.args[0]}",)


@dataclass(frozen=True)
class DeviceProfile:
    """The handle and its drive: ``mass`` kg, effective ``friction`` b N s/m (and where it
    comes from), drive scaling (0x606C, 0x6064, 0x6076 N m, transmission N/(N m), 0x6072), the
    ``velocity`` model of 0x606C.  ``coulomb_friction`` (N), ``velocity_noise`` (0x606C counts
    rms) and ``noise_seed`` are a simulated drive's hidden truth: the controller never uses them."""

    mass: float
    friction: float
    friction_source: str
    velocity_per_count: float
    position_per_count: float
    rated_torque: float
    force_per_torque: float
    max_torque_permille: int
    velocity: VelocityModel
    coulomb_friction: float = 0.0
    velocity_noise: float = 0.0
    noise_seed: int | None = None

    @property
    def max_force(self) -> float:
        """Handle force in N that 0x6072 allows: permille * rated torque * transmission / 1000."""
        return self.max_torque_permille * self.rated_torque * self.force_per_torque / 1000.0

    def scaling(self) -> DriveScaling:
        """The drive-unit conversion of :mod:`drives.base`."""
        return DriveScaling(self.velocity_per_count, self.position_per_count, self.rated_torque, self.force_per_torque,
                            self.max_torque_permille)

    def sim_parameters(self, period: float, timing: str, delay: float) -> dict[str, object]:
        """Keyword arguments of ``sim_drive.parameters.DeviceParameters`` for this device on a loop of
        ``period`` s and ``timing`` (with the hidden truth: Coulomb friction, velocity noise and its seed)."""
        parameters: dict[str, object] = {
            "m": self.mass, "b": self.friction, "period": period,
            "velocity_per_count": self.velocity_per_count, "position_per_count": self.position_per_count,
            "rated_torque": self.rated_torque, "force_per_torque": self.force_per_torque,
            "max_torque_permille": self.max_torque_permille, "velocity": self.velocity,
            "coulomb_friction": self.coulomb_friction, "velocity_noise": self.velocity_noise, "noise_seed": self.noise_seed}
        if timing == "reception":
            parameters["reception_delay"] = delay
        return parameters


@dataclass(frozen=True)
class LoopProfile:
    """The control loop: ``period`` T in s, ``timing`` ("ideal", "cia402" or "reception") and the
    loop ``delay`` D in samples (real; an int when whole) that the gate judges with."""

    period: float
    timing: str
    delay: float


@dataclass(frozen=True)
class Identification:
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


START_POLICIES = ("refuse", "ramp")


@dataclass(frozen=True)
class StartPolicy:
    """``[start]``: what a run does when the handle starts inside an object.  ``in_contact``:
    "refuse" (default: the drive is never enabled) or "ramp" (the scene's force from 0 to 1 over
    ``ramp_time`` s, every scaled wall on the way proven passive)."""

    in_contact: str = "refuse"
    ramp_time: float = 0.5


@dataclass(frozen=True)
class Profile:
    """A validated, gate-admitted operator parameter profile (SI units)."""

    name: str
    operator: str
    task: str
    description: str
    device: DeviceProfile
    loop: LoopProfile
    scene: tuple[SceneObject, ...]
    force_limit: float
    gate_policy: GatePolicy
    operator_model: Mapping[str, Any] = field(hash=False, compare=True)
    path: pathlib.Path | None = None
    safety: SafetySettings = field(default_factory=SafetySettings)
    supervisor: SupervisorPolicy = field(default_factory=SupervisorPolicy)
    start: StartPolicy = field(default_factory=StartPolicy)
    identification: Identification | None = None
    passivity: LayerPolicy = field(default_factory=LayerPolicy)

    def device_loop(self) -> DeviceLoop:
        """The loop the gate judges: m kg, effective b N s/m, T s, delay samples, velocity model."""
        d = self.device
        return DeviceLoop(d.mass, d.friction, self.loop.period, self.loop.delay, d.velocity)

    def scaling(self) -> DriveScaling:
        """The drive-unit conversion of :mod:`drives.base`."""
        return self.device.scaling()

    def compiled_scene(self) -> CompiledScene:
        """The scene as the piecewise-affine law the controller evaluates."""
        return compile_scene(self.scene)

    def gate(self) -> PassivityGate:
        """A passivity gate for this profile's loop and policy."""
        return PassivityGate(self.device_loop(), self.gate_policy)

    def sim_device_parameters(self) -> dict[str, object]:
        """Keyword arguments of ``sim_drive.parameters.DeviceParameters`` for this device and loop
        (with the hidden truth: Coulomb friction, velocity noise and its seed)."""
        return self.device.sim_parameters(self.loop.period, self.loop.timing, self.loop.delay)


# --------------------------------------------------------------------------- finding files

def _profiles_folder() -> pathlib.Path:
    return pathlib.Path(str(importlib.resources.files("profiles")))


def shipped_profiles(axes: bool = False) -> dict[str, pathlib.Path]:
    """The one-axis profiles shipped in the ``profiles`` package (``axes``: the multi-axis ones,
    those with ``[[axes]]``): name (file stem) -> path, sorted."""
    return {p.stem: p for p in sorted(_profiles_folder().glob("*.toml")) if ("axes" in read_document(p)) == axes}


def resolve_profile(path_or_name: str | pathlib.Path) -> pathlib.Path:
    """The file of a shipped profile name, or ``path_or_name`` as a path if it is one."""
    candidate = pathlib.Path(path_or_name)
    if candidate.is_file():
        return candidate
    shipped = {**shipped_profiles(), **shipped_profiles(axes=True)}
    if isinstance(path_or_name, str) and path_or_name in shipped:
        return shipped[path_or_name]
    raise ProfileError(path_or_name, "profile", str(path_or_name),
                       f"an existing TOML file or a shipped profile name: {', '.join(shipped) or 'none'}")


# --------------------------------------------------------------------------- validation

def _read_device(path: pathlib.Path, table: object) -> DeviceProfile:
    r = Reader(path, "device", table)
    mass = r.real("mass", *MASS_RANGE, "kg")
    friction = r.real("friction", *FRICTION_RANGE, "N s/m")
    source = r.text("friction_source")
    velocity = r.real("velocity_per_count", *SCALE_RANGE, "m/s per 0x606C unit", low_inclusive=False)
    position = r.real("position_per_count", *SCALE_RANGE, "m per 0x6064 increment", low_inclusive=False)
    rated = r.real("rated_torque", *RATED_TORQUE_RANGE, "N m (0x6076)")
    if not math.isclose(rated * 1000.0, round(rated * 1000.0), rel_tol=1e-12, abs_tol=1e-9):
        raise ProfileError(path, "device.rated_torque", rated, "a whole number of mN m (0x6076 is UNSIGNED32 in mN m)")
    transmission = r.real("force_per_torque", *SCALE_RANGE, "N/(N m)", low_inclusive=False)
    permille = r.whole("max_torque_permille", *PERMILLE_RANGE)
    model = r.velocity_model("velocity")
    coulomb = r.real("coulomb_friction", 0.0, 1e6, "N (a simulated drive's truth)", default=0.0)
    noise = r.real("velocity_noise", 0.0, 2.0**31, "0x606C counts rms (a simulated drive's truth)", default=0.0)
    seed = r.whole("noise_seed", *NOISE_SEED_RANGE, default=None) if "noise_seed" in r.table else None
    r.used.add("noise_seed")
    r.done()
    return DeviceProfile(mass, friction, source, velocity, position, rated, transmission, permille, model,
                         coulomb, noise, seed)


def _read_loop(path: pathlib.Path, table: object) -> LoopProfile:
    r = Reader(path, "loop", table)
    period = r.real("period", *PERIOD_RANGE, "s")
    timing = r.text("timing", choices=tuple(TIMINGS))
    least = TIMINGS[timing]
    low = 0.0 if least is None else least
    delay = r.real("delay", low, DELAY_RANGE[1], f"samples (timing {timing!r})", default=REQUIRED if least is None else least)
    r.done()
    return LoopProfile(period, timing, int(delay) if float(delay).is_integer() else delay)


def _read_identification(path: pathlib.Path, table: object) -> Identification | None:
    """``[identification]`` (optional): what ``haptic-bus identify`` measured (see :class:`Identification`)."""
    if table is None:
        return None
    r = Reader(path, "identification", table)
    date = r.text("date")
    values = {key: r.real(key, 0.0, high, unit) for key, high, unit in (
        ("mass", MASS_RANGE[1], "kg"), ("mass_stderr", MASS_RANGE[1], "kg"),
        ("friction", FRICTION_RANGE[1], "N s/m"), ("friction_stderr", FRICTION_RANGE[1], "N s/m"),
        ("coulomb_friction", 1e6, "N"), ("coulomb_friction_stderr", 1e6, "N"),
        ("delay", DELAY_RANGE[1], "samples"), ("delay_stderr", DELAY_RANGE[1], "samples"))}
    model = r.velocity_model("velocity")
    excitation = r.real("excitation_s", 0.0, 1e7, "s")
    residual = r.real("residual_rms", 0.0, 1e6, "m")
    r.done()
    return Identification(date, velocity=model, excitation_s=excitation, residual_rms=residual, **values)


def _check_against_identification(path: pathlib.Path, device: DeviceProfile, loop: LoopProfile,
                                  measured: Identification) -> None:
    """Refuse a ``[device]``/``[loop]`` more optimistic than what was measured: another velocity
    model (or a shorter window or filter), friction above the lowest credible, delay below the
    largest credible (:data:`CREDIBLE_SIGMAS` standard errors)."""
    declared, found = device.velocity, measured.velocity
    if declared.kind != found.kind or declared.time < found.time * (1.0 - 1e-9):
        raise ProfileError(path, "device.velocity", str(declared),
                           f"the model identification measured on {measured.date}: {found} (or a longer window or filter)")
    if device.friction > measured.lowest_credible_friction * (1.0 + 1e-9):
        raise ProfileError(path, "device.friction", device.friction,
                           f"at most {measured.lowest_credible_friction:.6g} N s/m, the lowest credible value measured on "
                           f"{measured.date} (b = {measured.friction:.6g} ± {measured.friction_stderr:.2g} N s/m)")
    if loop.delay < measured.largest_credible_delay - 1e-9:
        raise ProfileError(path, "loop.delay", loop.delay,
                           f"at least {measured.largest_credible_delay:.6g} samples, the largest credible delay measured "
                           f"on {measured.date} (D = {measured.delay:.6g} ± {measured.delay_stderr:.2g} samples)")


def _read_gate(path: pathlib.Path, table: object) -> GatePolicy:
    r = Reader(path, "gate", table)
    margin = r.real("safety_margin", 0.0, 1e12, "N s/m")
    bandwidth = r.text("bandwidth", choices=BANDWIDTH_POLICIES)
    r.done()
    return GatePolicy(margin, bandwidth)


def _read_safety(path: pathlib.Path, table: object) -> SafetySettings:
    """``[safety]`` (optional): heartbeat_ms, consumer_ms, rpdo_deadline_periods, abort_option
    ("fault", "disable-voltage", "quick-stop", "none"), strict, modbus_watchdog_ms (DESIGN 4.1)."""
    defaults = SafetySettings()
    if table is None:
        return defaults
    r = Reader(path, "safety", table)
    heartbeat = r.whole("heartbeat_ms", 1, 0xFFFF, default=defaults.heartbeat_ms)
    consumer = r.whole("consumer_ms", heartbeat + 1, 0xFFFF, default=max(defaults.consumer_ms, 3 * heartbeat))
    deadline = r.whole("rpdo_deadline_periods", 0, 10_000, default=defaults.rpdo_deadline_periods)
    option = r.text("abort_option", choices=tuple(ABORT_OPTIONS), default="fault")
    strict = r.flag("strict", default=defaults.strict)
    watchdog = r.whole("modbus_watchdog_ms", 0, 0xFFFF, default=defaults.modbus_watchdog_ms)
    r.done()
    return SafetySettings(defaults.master_node_id, heartbeat, consumer, deadline, ABORT_OPTIONS[option], strict, watchdog)


def _read_passivity(path: pathlib.Path, table: object) -> LayerPolicy:
    """``[passivity]`` (optional): layer ("off", "guard", "bound"), budget_cap (J), beyond_gate."""
    defaults = LayerPolicy()
    if table is None:
        return defaults
    r = Reader(path, "passivity", table)
    layer = r.text("layer", choices=LAYER_MODES, default=defaults.layer)
    cap = r.real("budget_cap", 0.0, 1e6, "J", low_inclusive=False) if "budget_cap" in r.table else None
    beyond = r.flag("beyond_gate", default=False)
    r.done()
    if beyond and layer != "bound":
        raise ProfileError(path, "passivity.beyond_gate", True, 'false unless layer = "bound" (only the bound '
                           "guarantees passivity for walls the gate refuses)")
    return LayerPolicy(layer, cap, beyond)


def _read_supervisor(path: pathlib.Path, table: object, passivity: LayerPolicy) -> SupervisorPolicy:
    """``[supervisor]`` (optional): on_late, on_observer ("warn", "derate", "stop"), late_tolerance
    (fraction of T), late_window (cycles), late_limit (cycles), observer_limit (J).  A late cycle
    is a warning while a passivity layer holds the port passive, and stops a run without one."""
    defaults = SupervisorPolicy(on_late=Action.WARN.value if passivity.layer != "off" else Action.STOP.value)
    if table is None:
        return defaults
    r = Reader(path, "supervisor", table)
    actions = tuple(a.value for a in Action)
    on_late = r.text("on_late", choices=actions, default=defaults.on_late)
    tolerance = r.real("late_tolerance", 0.0, 100.0, "of the period T", low_inclusive=False, default=defaults.late_tolerance)
    window = r.whole("late_window", 1, 1_000_000, default=defaults.late_window)
    limit = r.whole("late_limit", 0, window - 1, default=min(defaults.late_limit, window - 1))
    on_observer = r.text("on_observer", choices=actions, default=defaults.on_observer)
    observer_limit = r.real("observer_limit", 0.0, 1e6, "J", default=defaults.observer_limit)
    r.done()
    return SupervisorPolicy(on_late, tolerance, window, limit, on_observer, observer_limit)


def _read_start(path: pathlib.Path, table: object) -> StartPolicy:
    """``[start]`` (optional): in_contact ("refuse" or "ramp"), ramp_time (s)."""
    defaults = StartPolicy()
    if table is None:
        return defaults
    r = Reader(path, "start", table)
    policy = StartPolicy(r.text("in_contact", choices=START_POLICIES, default=defaults.in_contact),
                         r.real("ramp_time", 0.0, 3600.0, "s", low_inclusive=False, default=defaults.ramp_time))
    r.done()
    return policy


def _read_object(path: pathlib.Path, index: int, table: object) -> SceneObject:
    r = Reader(path, f"scene.objects[{index}]", table)
    kind = r.text("kind", choices=("wall", "slot", "detent"))
    name = r.text("name", pattern=NAME_PATTERN)
    stiffness = r.real("stiffness", *STIFFNESS_RANGE, "N/m")
    damping = r.real("damping", *DAMPING_RANGE, "N s/m")
    if kind == "wall":
        position = r.real("position", *POSITION_RANGE, "m")
        normal = r.raw("normal", "-1 (solid above position, pushed into in +x) or +1 (solid below)")
        if isinstance(normal, bool) or normal not in (-1, 1):
            raise ProfileError(path, r.field("normal"), normal, "-1 (solid above position) or +1 (solid below)")
        r.done()
        return Wall(name, position, int(normal), stiffness, damping)
    if kind == "slot":
        low = r.real("low", *POSITION_RANGE, "m")
        high = r.real("high", *POSITION_RANGE, "m")
        if not high > low:
            raise ProfileError(path, r.field("high"), high, f"greater than low = {low:g} m")
        r.done()
        return Slot(name, low, high, stiffness, damping)
    center = r.real("center", *POSITION_RANGE, "m")
    reach = r.real("reach", 0.0, 1e6, "m", low_inclusive=False)
    r.done()
    return Detent(name, center, reach, stiffness, damping)


def _read_scene(path: pathlib.Path, table: object) -> tuple[SceneObject, ...]:
    r = Reader(path, "scene", table)
    objects = r.raw("objects", "an array of tables [[scene.objects]] (may be empty)", default=[])
    if not isinstance(objects, list):
        raise ProfileError(path, "scene.objects", objects, "an array of tables [[scene.objects]]")
    r.done()
    scene = tuple(_read_object(path, i, obj) for i, obj in enumerate(objects))
    seen: dict[str, int] = {}
    for i, obj in enumerate(scene):
        if obj.name in seen:
            raise ProfileError(path, f"scene.objects[{i}].name", obj.name,
                               f"a name no other object uses (scene.objects[{seen[obj.name]}] has it)")
        seen[obj.name] = i
    return scene


def _read_operator_model(path: pathlib.Path, table: object) -> Mapping[str, Any]:
    if table is None:
        return types.MappingProxyType({"model": "none"})
    r = Reader(path, "operator_model", table)
    names = tuple(OPERATOR_FIELDS) + tuple(OPERATOR_ALIASES)
    model = OPERATOR_ALIASES.get(name := r.text("model", choices=names), name)
    out: dict[str, Any] = {"model": model}
    if model == "recorded":
        given = r.text("path")
        csv = (path.parent / given).resolve()
        if not csv.is_file():
            raise ProfileError(path, "operator_model.path", given,
                               f"a CSV file (time s, force N), relative to {path.parent}")
        out["path"] = str(csv)
        out["interpolation"] = r.text("interpolation", choices=INTERPOLATIONS, default="hold")
    for key, (low, high, unit, default) in OPERATOR_FIELDS[model].items():
        low_inclusive = not (model == "chirp" and key == "duration")
        out[key] = r.real(key, low, high, unit, low_inclusive=low_inclusive, default=default)
    r.done()
    return types.MappingProxyType(out)


def read_profile(path_or_name: str | pathlib.Path) -> Profile:
    """Parse and validate a profile file (or shipped name) without judging it; raise ProfileError."""
    path = resolve_profile(path_or_name)
    document = read_document(path)
    if "axes" in document:  # a multi-axis profile: its own reader (haptic_bus.app.axes_profile)
        raise ProfileError(path, "axes", "[[axes]]",
                           "no [[axes]] in a one-axis profile; multi-axis profiles load with load_axes_profile")
    top = Reader(path, "", document)
    meta = Reader(path, "profile", top.raw("profile", "a [profile] table"))
    name = meta.text("name", pattern=NAME_PATTERN)
    operator = meta.text("operator")
    task = meta.text("task")
    description = meta.text("description")
    meta.done()
    device = _read_device(path, top.raw("device", "a [device] table"))
    loop = _read_loop(path, top.raw("loop", "a [loop] table"))
    limits = Reader(path, "limits", top.raw("limits", "a [limits] table"))
    allowed_force = device.max_force
    force_limit = limits.real("force_limit", *FORCE_RANGE, "N", low_inclusive=False)
    limits.done()
    if force_limit > allowed_force * (1 + 1e-12):
        raise ProfileError(
            path, "limits.force_limit", force_limit,
            f"(0, {allowed_force:g}] N, the force 0x6072 allows: max_torque_permille {device.max_torque_permille}"
            f" * rated_torque {device.rated_torque:g} N m * force_per_torque {device.force_per_torque:g} N/(N m) / 1000")
    policy = _read_gate(path, top.raw("gate", "a [gate] table"))
    scene = _read_scene(path, top.raw("scene", "a [scene] table with [[scene.objects]]"))
    operator_model = _read_operator_model(path, top.raw("operator_model", "", default=None))
    safety = _read_safety(path, top.raw("safety", "a [safety] table", default=None))
    passivity = _read_passivity(path, top.raw("passivity", "a [passivity] table", default=None))
    supervisor = _read_supervisor(path, top.raw("supervisor", "a [supervisor] table", default=None), passivity)
    start = _read_start(path, top.raw("start", "a [start] table", default=None))
    identification = _read_identification(path, top.raw("identification", "an [identification] table", default=None))
    top.done()
    if identification is not None:
        _check_against_identification(path, device, loop, identification)
    try:  # the model against the period: a velocity window longer than T is no model of this loop
        device.velocity.check_period(loop.period)
    except ParameterError as error:
        raise ProfileError(path, "device.velocity", error.value, error.allowed) from None
    return Profile(name, operator, task, description, device, loop, scene, force_limit, policy,
                   operator_model, path, safety, supervisor, start, identification, passivity)


def load_profile(path_or_name: str | pathlib.Path) -> Profile:
    """Read, validate and gate a profile; raise ProfileError (invalid) or ProfileRefusal (not passive,
    unless the profile runs beyond the gate under the bound layer: ``[passivity] beyond_gate``)."""
    profile = read_profile(path_or_name)
    decision = profile.gate().judge(profile.compiled_scene())
    if not decision.accepted and not profile.passivity.beyond_gate:
        raise ProfileRefusal(profile.path or profile.name, decision)
    return profile


def default_profile() -> Profile:
    """The shipped :data:`DEFAULT_PROFILE` (the one ``haptic-bus demo`` runs)."""
    return load_profile(DEFAULT_PROFILE)


def profile_to_dict(profile: Profile) -> dict[str, Any]:
    """A JSON-ready view of a profile (SI units, as in the TOML)."""
    d = profile.device
    return {
        "profile": {"name": profile.name, "operator": profile.operator, "task": profile.task,
                    "description": profile.description},
        "path": None if profile.path is None else str(profile.path),
        "device": {k: str(v) if isinstance(v, VelocityModel) else v for k, v in vars(d).items()} | {"max_force": d.max_force},
        "loop": {"period": profile.loop.period, "timing": profile.loop.timing, "delay": profile.loop.delay},
        "identification": None if profile.identification is None else {
            k: str(v) if isinstance(v, VelocityModel) else v for k, v in vars(profile.identification).items()},
        "limits": {"force_limit": profile.force_limit},
        "gate": {"safety_margin": profile.gate_policy.safety_margin, "bandwidth": profile.gate_policy.bandwidth},
        "scene": {"objects": [object_to_dict(o) for o in profile.scene]},
        "operator_model": dict(profile.operator_model),
        "safety": {k: getattr(profile.safety, k) for k in profile.safety.__dataclass_fields__ if k != "master_node_id"},
        "supervisor": {k: getattr(profile.supervisor, k) for k in profile.supervisor.__dataclass_fields__},
        "passivity": dataclasses.asdict(profile.passivity),
        "start": {k: getattr(profile.start, k) for k in profile.start.__dataclass_fields__},
    }
