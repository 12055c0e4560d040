"""The bench's layer table prints only figures its header describes: the share of the asked force
the targets carried, in [0, 1] or n/a, and the most the layer took off one target, within the
profile's force limit (the column names are the record's own, not a copied list)."""

from __future__ import annotations

import numpy as np
import pytest

from haptic_bus.app.profiles import load_profile
from haptic_bus.bench.layer_cost import measure, reached_share
from haptic_bus.bench.report import _layer


def test_the_share_counts_what_went_out_in_the_asked_direction_at_most_what_was_asked():
    asked = np.array([0.0, 10.0, -10.0, 5.0, 2.0])
    applied = np.array([3.0, 10.0004, -4.0, -1.0, 1.5])  # rounded above, lowered, reversed, lowered
    # carried 10 + 4 + 0 + 1.5 of 27 asked; the cycle out of contact (asked 0) does not count
    assert reached_share(asked, applied) == pytest.approx(15.5 / 27.0, rel=1e-15)
    assert reached_share(np.zeros(3), np.ones(3)) is None


@pytest.mark.parametrize("adversarial", [False, True])
def test_a_measured_row_is_a_share_and_a_force_within_the_limit(adversarial: bool):
    """0.2 s of virtual time of the shipped handle under the bound layer; a per-mille step (the
    targets' resolution) is the only slack on the force limit."""
    profile = load_profile("cia402-handle")
    row = measure("cia402-handle", "bound", adversarial, 0.2)
    assert row["reached"] is not None and 0.0 <= row["reached"] <= 1.0
    step = profile.device.scaling().newton_per_permille
    assert 0.0 <= row["removed_max"] <= profile.force_limit + step
    assert row["cycles"] == 200


def test_the_table_says_n_a_without_contact():
    row = {"profile": "p", "timing": "nominal", "layer": "off", "lowered": 0.0, "reached": None, "removed_max": 0.0,
           "least_energy": 0.0}
    table = "\n".join(_layer({"seconds": 0.2, "seed": 1, "rows": [row]}))
    assert "| n/a (no contact) |" in table and "wall force sent" in table
