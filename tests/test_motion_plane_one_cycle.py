"""The plane of motion of a run with one cycle (``haptic-bus demo --profile gantry-3d --duration 1e-9``,
or a three-axis run killed after its first cycle): one position spans no direction, and the figure
used to fail on it with an IndexError (the SVD of one row has one direction)."""

from __future__ import annotations

import numpy as np

from haptic_bus.app.trajectory_plot import motion_plane


def test_one_position_gives_the_plane_of_the_first_two_axes_through_it() -> None:
    point = np.array([[0.01, -0.022, 0.003]])  # m
    origin, basis = motion_plane(point)
    assert origin.tolist() == point[0].tolist()
    assert basis.tolist() == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]


def test_two_positions_or_more_keep_their_principal_plane() -> None:
    # three points on the plane z = 0.004 m, spread along x and y: the plane found is that one
    points = np.array([[0.0, 0.0, 0.004], [0.01, 0.0, 0.004], [0.0, 0.02, 0.004]])
    _, basis = motion_plane(points)
    assert basis.shape == (2, 3)
    normal = np.cross(basis[0], basis[1])
    assert abs(abs(normal[2]) - 1.0) < 1e-12  # unit vectors from an SVD: orthonormal to round-off
