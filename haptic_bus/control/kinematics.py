"""Kinematics: from the axes' joint coordinates ``q`` to the handle's Cartesian position, and back for forces.

A device maps its joint coordinates ``q`` (one per axis: m for a linear axis, rad for a rotary
one) to the handle's position ``x = f(q)`` (m); its Jacobian ``J(q) = df/dq`` maps joint
velocities to the handle's, ``v = J q_dot``, and, by the principle of virtual work, a force
``F`` on the handle (N) to joint efforts ``tau = J^T F`` (N for a linear axis, N m for a
rotary one).  A scene in space (:mod:`haptic_bus.control.space_scene`) lives in ``x``; each
drive takes its own ``tau_i``.

Implemented: :class:`Cartesian` (every axis one direction of space, ``J = I``: a gantry), the
device the coupled gate (:mod:`haptic_bus.analysis.coupled`) judges exactly -- its joint-space
mass and friction are the axes' own diagonal ``m_i``, ``b_i``.  Any other device (a serial or
parallel linkage) implements :class:`Kinematics`; the gate then needs its task-space mass
``J^-T M(q) J^-1``, which is neither diagonal nor constant -- not covered yet.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.coupled_loop import MAX_AXES
from haptic_bus.errors import ParameterError


class Kinematics(Protocol):
    """What a device's geometry offers the controller: positions, Jacobian, forces to joint efforts."""

    @property
    def size(self) -> int:
        """Number of axes (joint coordinates) and of Cartesian coordinates."""
        ...

    def position(self, q: ArrayLike) -> np.ndarray:
        """The handle's position ``x = f(q)`` (m)."""
        ...

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """``J(q) = df/dq``: ``size x size``."""
        ...


def joint_efforts(kinematics: Kinematics, q: ArrayLike, force: ArrayLike) -> np.ndarray:
    """``tau = J(q)^T F``: the joint efforts (N or N m per axis) that put the force ``F`` (N) on the handle."""
    return kinematics.jacobian(q).T @ np.asarray(force, dtype=float)


def handle_velocity(kinematics: Kinematics, q: ArrayLike, q_dot: ArrayLike) -> np.ndarray:
    """``v = J(q) q_dot``: the handle's velocity (m/s) from the joints' rates."""
    return kinematics.jacobian(q) @ np.asarray(q_dot, dtype=float)


class Cartesian:
    """A Cartesian device: axis ``i`` moves the handle along coordinate ``i`` (m); ``x = q``, ``J = I``."""

    def __init__(self, size: int) -> None:
        if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_AXES:
            raise ParameterError("axes", size, f"an integer in [1, {MAX_AXES}]", "Cartesian kinematics")
        self._size = size
        self._identity = np.eye(size)
        self._identity.setflags(write=False)

    @property
    def size(self) -> int:
        """Number of axes."""
        return self._size

    def position(self, q: ArrayLike) -> np.ndarray:
        """``x = q`` (m)."""
        return self._checked(q).copy()

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """``J = I``, whatever ``q``."""
        self._checked(q)
        return self._identity

    def _checked(self, q: ArrayLike) -> np.ndarray:
        values = np.asarray(q, dtype=float)
        if values.shape != (self._size,):
            raise ParameterError("q", np.asarray(q).tolist(), f"{self._size} joint coordinates", "Cartesian kinematics")
        return values
