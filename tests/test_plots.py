"""The figure writers produce real, non-trivial PNGs (their content is checked by eye)."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.app.plots import plot_nyquist, plot_region, plot_step

SEED = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 0)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _check_png(path):
    assert path.exists()
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    assert path.stat().st_size > 20_000  # bytes: axes, curves and text, not a blank canvas
    image = mpimg.imread(path)
    assert image.shape[0] > 300 and image.shape[1] > 500
    assert np.std(image[..., :3]) > 0.05  # not a single colour


@pytest.mark.parametrize("delay", [0, 1])
def test_plot_region(tmp_path, delay):
    loop = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, delay)
    path = plot_region(tmp_path / f"region{delay}.png", 0.5, 0.1, 1e-3, delay, point=loop)
    _check_png(path)


def test_plot_region_with_pair_point(tmp_path):
    _check_png(plot_region(tmp_path / "sub" / "region.png", 0.04, 0.8, 1e-3, 0, point=(20.0, 0.5)))


@pytest.mark.parametrize("delay", [0, 1])
def test_plot_nyquist(tmp_path, delay):
    _check_png(plot_nyquist(tmp_path / "nyquist.png", WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, delay)))


@pytest.mark.parametrize("delay", [0, 1])
def test_plot_step(tmp_path, delay):
    _check_png(plot_step(tmp_path / "step.png", WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, delay)))
