"""``DriveScaling.torque_permille``: the force's quotient in the force's own type, rounded half to even."""

from __future__ import annotations

from decimal import Decimal

import numpy as np
import pytest

from drives.base import DriveScaling
from drives.errors import ParameterError

SCALING = DriveScaling(velocity_per_count=1e-6, position_per_count=1e-6, rated_torque=0.1, force_per_torque=100.0)
# newton_per_permille = 0.1 * 100 / 1000 = 0.01 N


@pytest.mark.parametrize("force, permille", [
    (0.015, 2),  # 1.5 in doubles, half to even
    (np.float64(0.015), 2),
    (np.float32(0.015), 2),  # float32: 0.015f / 0.01 is 1.5f exactly, half to even: 2 (a float64 division gives 1)
    (np.float32(0.025), 2),  # 2.5f, half to even
    (-0.0, 0),
    (3, 300),
    (np.int64(-7), -700),
])
def test_the_quotient_is_taken_in_the_forces_own_type(force: float, permille: int) -> None:
    assert SCALING.torque_permille(force) == permille
    assert SCALING.torque_permille(force) == round(force / SCALING.newton_per_permille)


@pytest.mark.parametrize("force", ["1.5", Decimal("1.5")])
def test_a_force_that_is_no_number_is_refused(force: object) -> None:
    with pytest.raises(TypeError):
        SCALING.torque_permille(force)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", [0, -1e-6, float("inf"), float("nan"), True, "1e-6"])
def test_a_scaling_factor_that_is_no_finite_real_above_zero_is_refused(value: object) -> None:
    """The shared range check (drives.ranges.real_in_range) with no upper bound: its words, the field named."""
    with pytest.raises(ParameterError) as refused:
        DriveScaling(velocity_per_count=1e-6, position_per_count=value, rated_torque=0.1,  # type: ignore[arg-type]
                     force_per_torque=100.0)
    assert str(refused.value) == (f"drive scaling: position_per_count = {value!r} is invalid; allowed: a finite real > 0")
