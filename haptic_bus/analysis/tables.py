"""The README's table: the largest passive spring at ``B = 0`` by velocity model and delay, per device.

For each device (``m`` kg, ``b`` N s/m, ``T`` s), each velocity model the drive may report and
each loop delay ``D`` (samples), the largest passive ``K`` (N/m) without a damper, from the exact
criterion (:func:`haptic_bus.analysis.limits.passive_set`).  It shows what choosing a drive
means: which velocity it puts in 0x606C and when it applies the torque decide the wall more
than the wall's own parameters do.
"""

from __future__ import annotations

from dataclasses import dataclass

from haptic_bus.analysis.limits import passive_set
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.velocity import VelocityModel


@dataclass(frozen=True)
class Device:
    """A handle: ``name``, mass ``m`` kg, effective friction ``b`` N s/m, period ``T`` s."""

    name: str
    m: float
    b: float
    T: float


DEVICES = (
    Device("seed (m 0.5 kg, b 0.1 N s/m)", 0.5, 0.1, 1e-3),
    Device("cia402-handle (m 1.0 kg, b 20 N s/m)", 1.0, 20.0, 1e-3),  # profiles/cia402-handle.toml
    Device("desktop-omni (m 0.032 kg, b 3.62 N s/m)", 0.032, 3.62, 1e-3),  # profiles/desktop-omni.toml
)
LOWPASS_TAU = 0.5e-3  # s: a typical drive's velocity filter, T/2 at 1 kHz
VELOCITY_MODELS = ("point", "average", f"lowpass:{LOWPASS_TAU!r}")
DELAYS = (0.0, 0.25, 0.5, 1.0)


def largest_stiffness(device: Device, velocity: str, delay: float) -> float | None:
    """Largest passive ``K`` (N/m) at ``B = 0`` for ``device`` with ``velocity`` and ``delay`` (samples)."""
    loop = WallLoop(device.m, device.b, device.T, 0.0, 0.0, delay, VelocityModel.parse(velocity))
    return passive_set(loop, "K").largest


def stiffness_table(devices: tuple[Device, ...] = DEVICES, velocities: tuple[str, ...] = VELOCITY_MODELS,
                    delays: tuple[float, ...] = DELAYS) -> list[tuple[str, str, list[float | None]]]:
    """Rows ``(device, velocity model, [largest passive K at B = 0 for each delay])``, N/m."""
    return [(dev.name, vel, [largest_stiffness(dev, vel, d) for d in delays]) for dev in devices for vel in velocities]


def stiffness_table_markdown(devices: tuple[Device, ...] = DEVICES, velocities: tuple[str, ...] = VELOCITY_MODELS,
                             delays: tuple[float, ...] = DELAYS) -> str:
    """:func:`stiffness_table` as a markdown table (K in N/m, 4 significant digits; "none": no passive K)."""
    head = "| device | velocity | " + " | ".join(f"D = {d:g}" for d in delays) + " |"
    rule = "|---|---|" + "---:|" * len(delays)
    lines = [head, rule]
    for name, velocity, values in stiffness_table(devices, velocities, delays):
        cells = ["none" if k is None else f"{k:.4g}" for k in values]
        lines.append(f"| {name} | {velocity} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
