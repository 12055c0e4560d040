"""The manual's table (docs/passivity.md): largest passive K at B = 0 by velocity model and delay,
checked against theory, and the page shows what the code computes.

Anchors: point velocity without delay is eq. 23's flip ``K = 2 b / (T tanh(c/2))``; average
velocity without delay is Colgate's position-sampled wall ``b >= K T/2``; in between, a spring
lagging ``tau`` acts as a damping ``-K tau`` at low frequency (DESIGN 3.5), so ``K ~ b / tau``
with ``tau = delta T`` (point), ``T/2 + D T`` (average), ``TAU + D T`` (low-pass): the exact
values agree with that rule to the rule's own ``O(c)`` accuracy (1e-3 here).
"""

from __future__ import annotations

import math
import pathlib

import pytest

from haptic_bus.analysis.tables import DEVICES, LOWPASS_TAU, largest_stiffness, stiffness_table, stiffness_table_markdown

SEED_DEVICE = DEVICES[0]
REPO = pathlib.Path(__file__).resolve().parents[1]


def test_the_zero_delay_anchors_are_eq23_and_colgate() -> None:
    b, T, m = SEED_DEVICE.b, SEED_DEVICE.T, SEED_DEVICE.m
    flip = 2 * b / (T * math.tanh(b * T / (2 * m)))
    assert largest_stiffness(SEED_DEVICE, "point", 0.0) == pytest.approx(flip, rel=1e-12)
    assert largest_stiffness(SEED_DEVICE, "average", 0.0) == pytest.approx(2 * b / T, rel=1e-6)


@pytest.mark.parametrize("velocity,lag", [("point", 0.0), ("average", 0.5), (f"lowpass:{LOWPASS_TAU!r}", 0.5)])
@pytest.mark.parametrize("delay", [0.25, 0.5, 1.0])
def test_the_lag_rule_holds_for_the_seed_device(velocity: str, lag: float, delay: float) -> None:
    tau = (lag + delay) * SEED_DEVICE.T
    assert largest_stiffness(SEED_DEVICE, velocity, delay) == pytest.approx(SEED_DEVICE.b / tau, rel=1e-3)


def test_the_markdown_table_has_every_device_model_and_delay() -> None:
    rows = stiffness_table()
    assert len(rows) == 9 and all(len(values) == 4 for _, _, values in rows)
    text = stiffness_table_markdown()
    assert text.count("\n") == 10 and "| D = 0.25 |" in text and "cia402-handle" in text and "desktop-omni" in text
    assert text.strip() in (REPO / "docs" / "passivity.md").read_text()  # the page's copy is the table, every digit
