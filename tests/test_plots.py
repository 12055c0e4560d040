"""The figure writers produce real, non-trivial PNGs (their content is checked by eye).

The seed's own figures (delay 0) are drawn once, by ``haptic-bus report seed-ideal`` (the real
command line in this process): the same three writer calls on the same loop, checked here as
the writers' other PNGs are; the writers' own tests draw the one-sample-delay loop."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.app.cli import main
from haptic_bus.app.plots import plot_nyquist, plot_region, plot_step

SEED_D1 = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 1)  # the seed's wall behind one sample of delay
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _check_png(path):
    assert path.exists()
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    assert path.stat().st_size > 20_000  # bytes: axes, curves and text, not a blank canvas
    image = mpimg.imread(path)
    assert image.shape[0] > 300 and image.shape[1] > 500
    assert np.std(image[..., :3]) > 0.05  # not a single colour


def test_report_writes_the_seed_figures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["report", "seed-ideal", "--out", str(tmp_path)]) == 0
    for name in ("fig4_region.png", "fig5_nyquist.png", "fig6_step.png"):
        _check_png(tmp_path / name)
    summary = (tmp_path / "report.md").read_text()
    assert "verdict: passive" in summary and "margin +0.0998139 N s/m" in summary


def test_plot_region(tmp_path):
    _check_png(plot_region(tmp_path / "region1.png", 0.5, 0.1, 1e-3, 1, point=SEED_D1))


def test_plot_region_with_pair_point(tmp_path):
    _check_png(plot_region(tmp_path / "sub" / "region.png", 0.04, 0.8, 1e-3, 0, point=(20.0, 0.5)))


def test_plot_nyquist(tmp_path):
    _check_png(plot_nyquist(tmp_path / "nyquist.png", SEED_D1))


def test_plot_step(tmp_path):
    _check_png(plot_step(tmp_path / "step.png", SEED_D1))
