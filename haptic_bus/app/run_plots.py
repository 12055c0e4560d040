"""PNG plots of a run's record: handle position and wall force over time."""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from haptic_bus.control.record import RunRecord


def plot_run(path: str | pathlib.Path, record: RunRecord, title: str, walls_at: list[float] | None = None) -> pathlib.Path:
    """Position (mm), wall force (N) and the observer's interface energy (mJ) over time (s), one PNG."""
    t = record.column("time_s")
    fig, (ax_x, ax_f, ax_e) = plt.subplots(3, 1, sharex=True, figsize=(8, 7.5))
    ax_x.plot(t, record.column("position_m") * 1e3, color="tab:blue", label="handle position")
    for at in walls_at or []:
        ax_x.axhline(at * 1e3, color="tab:gray", linestyle="--", linewidth=1, label=f"wall surface {at * 1e3:g} mm")
    ax_x.set_ylabel("position (mm)")
    ax_x.legend(loc="best")
    ax_f.plot(t, record.column("force_n"), color="tab:red", label="wall force u")
    ax_f.set_ylabel("force (N)")
    ax_f.legend(loc="best")
    ax_e.plot(t, record.column("energy_j") * 1e3, color="tab:green",
              label="interface energy (observer: stored at start + wall + b v² + kinetic)")
    ax_e.axhline(0.0, color="black", linewidth=0.8)
    ax_e.set_ylabel("energy (mJ)")
    ax_e.set_xlabel("time (s)")
    ax_e.legend(loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
