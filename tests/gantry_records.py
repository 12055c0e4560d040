"""The records of a gantry-3d run (one ``record-<axis>.csv`` per axis) and what they show at rest on
the slope: shared by the CANopen and the Modbus multi-axis tests, not a test module."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from haptic_bus.app.steady_state import contact
from haptic_bus.control.space_scene import SpaceScene

AXES = "xyz"
TIMES = ("compute_s", "wall_clock_s", "monotonic_s")  # when and how long the machine took: not the loop's


def records(folder: pathlib.Path) -> dict[str, np.ndarray]:
    """Every axis' record in ``folder``, by axis name (columns by their headers)."""
    return {axis: np.genfromtxt(folder / f"record-{axis}.csv", delimiter=",", names=True) for axis in AXES}


def assert_same_loop(first: dict[str, np.ndarray], second: dict[str, np.ndarray]) -> None:
    """Two runs' records equal bit for bit in every column but :data:`TIMES`."""
    for axis in AXES:
        for column in first[axis].dtype.names:
            if column not in TIMES:
                assert np.array_equal(first[axis][column], second[axis][column]), (axis, column)


def assert_resting_on_the_slope(last: dict[str, np.ndarray], scene: SpaceScene) -> None:
    """The run's last cycle at rest in contact with the slope, the hand's 3 N answered: the wall force
    along the slope's normal ``K`` times the depth at the measured position (to 1e-9: the controller's
    own arithmetic, no rounding between), the torques -400, -400, -200 per mille."""
    x = np.array([last[axis]["position_m"][-1] for axis in AXES])
    touching = contact(scene, x)
    assert touching is not None and touching[0] == "slope"
    _, stiffness, depth, normal = touching
    wall = np.array([last[axis]["force_n"][-1] for axis in AXES])
    assert [last[axis]["velocity_m_per_s"][-1] for axis in AXES] == [0.0, 0.0, 0.0]
    assert -float(np.dot(wall, normal)) == pytest.approx(stiffness * depth, rel=1e-9)
    assert [int(last[axis]["torque_permille"][-1]) for axis in AXES] == [-400, -400, -200]
