"""Draw ``docs/figures/quantisation.png``: the issue's wall (m 0.032 kg, b 3.62 N s/m, T 1 ms, K 1500 N/m,
B 0, average velocity, D 1, Delta 5e-5 m) pushed in by a constant 1.5 K Delta = 0.1125 N, which parks it
between the wall's levels K Delta and 2 K Delta (net force +- K Delta/2 = 0.0375 N), with a hand damping of
b, for three Coulomb frictions: 0 and 0.03 N (below K Delta/2: it never sticks, a limit cycle across the
level at 2 Delta from which the hand takes energy out for ever) and 0.1 N (it stops and sticks).

Run from the repository's root: ``python docs/figures/quantisation.py`` (exact simulation, a few seconds).
"""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.quantised_loop import Hand, Quantiser, simulate_quantised

LOOP = WallLoop(0.032, 3.62, 1e-3, 1500.0, 0.0, 1, "average")
DELTA = 5e-5  # m per count
SAMPLES = 12000
OUT = pathlib.Path(__file__).with_suffix(".png")


def main() -> None:
    """Simulate the three frictions and write the PNG."""
    hand = Hand((1.5 * LOOP.K * DELTA,) * SAMPLES, 1, LOOP.b)
    t = np.arange(SAMPLES) * LOOP.T
    figure, (top, middle, bottom) = plt.subplots(3, 1, figsize=(8, 8.5), constrained_layout=True)
    for coulomb, colour in ((0.0, "tab:red"), (0.03, "tab:orange"), (0.1, "tab:blue")):
        run = simulate_quantised(LOOP, hand, Quantiser(DELTA), coulomb, start=0.999 * DELTA)
        label = f"f_c = {coulomb:g} N"
        zoom = t < 0.06
        top.plot(t[zoom] * 1e3, run.position[zoom] / DELTA, color=colour, label=label)
        if coulomb == 0.0:  # the count the wall uses (x_k = Delta n_k): a sample behind the handle
            top.step(t[zoom] * 1e3, run.wall_position[zoom] / DELTA, where="post", color=colour, lw=0.8, ls=":",
                     label="the wall's x_k / Delta at 0 N")
        middle.step(t[zoom] * 1e3, run.wall_force[zoom], where="post", color=colour, label=label)
        bottom.plot(t, run.energy * 1e6, color=colour, label=f"{label}: least E {run.least_energy * 1e6:+.3f} uJ")
    for level in (1.0, 2.0):
        top.axhline(level, color="grey", lw=0.8, ls="--")
    top.set(ylabel="true position x(kT) / Delta", title="encoder levels dashed; K Delta/2 = 0.0375 N")
    middle.set(ylabel="wall force u_k (N)", xlabel="t (ms)")
    bottom.axhline(0.0, color="grey", lw=0.8)
    bottom.set(ylabel="operator energy E (uJ)", xlabel="t (s)",
               title="a hand damping of b = 3.62 N s/m takes the limit cycle's energy out")
    for axes in (top, middle, bottom):
        axes.grid(alpha=0.3)
        axes.legend(loc="best", fontsize=8)
    figure.savefig(OUT, dpi=90)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
