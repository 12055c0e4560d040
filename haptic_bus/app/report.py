"""``haptic-bus report``: the seed's Figs. 4, 5 and 6 for a profile, and a markdown summary."""

from __future__ import annotations

import pathlib

from haptic_bus.analysis.check import check_loop, format_check
from haptic_bus.app.plots import plot_nyquist, plot_region, plot_step
from haptic_bus.app.profiles import Profile


def write_report(profile: Profile, out_dir: str | pathlib.Path) -> list[pathlib.Path]:
    """Write ``fig4_region.png``, ``fig5_nyquist.png``, ``fig6_step.png`` per contact wall
    (the stiffest first) and ``report.md`` to ``out_dir``; return the paths."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    device = profile.device_loop()
    decision = profile.gate().judge(profile.compiled_scene())
    walls = sorted(decision.walls, key=lambda w: (-w.K, -w.B))
    written: list[pathlib.Path] = []
    main = device.wall(walls[0].K, walls[0].B) if walls else None
    written.append(plot_region(out / "fig4_region.png", device.m, device.b, device.T, delay=device.delay, point=main,
                               velocity=device.velocity))
    lines = [
        f"# {profile.name}",
        "",
        profile.description,
        "",
        f"- operator: {profile.operator}",
        f"- task: {profile.task}",
        f"- device: m = {device.m:g} kg, effective b = {device.b:g} N s/m ({profile.device.friction_source})",
        f"- loop: T = {device.T:g} s, {profile.loop.timing} timing, delay D = {device.delay:g} samples; "
        f"velocity: {profile.device.velocity}",
        f"- gate: {'accepted' if decision.accepted else 'REFUSED'} with safety margin "
        f"{profile.gate_policy.safety_margin:g} N s/m, bandwidth rule {profile.gate_policy.bandwidth}",
        "",
        "![Fig. 4](fig4_region.png)",
    ]
    for i, wall in enumerate(walls):
        loop = device.wall(wall.K, wall.B)
        suffix = "" if i == 0 else f"_{i}"
        nyquist = plot_nyquist(out / f"fig5_nyquist{suffix}.png", loop)
        step = plot_step(out / f"fig6_step{suffix}.png", loop)
        written += [nyquist, step]
        report = format_check(check_loop(loop, quantisation=device.quantisation))
        lines += ["", f"## {' + '.join(wall.objects)}: K = {wall.K:g} N/m, B = {wall.B:g} N s/m", "", "```",
                  report, "```", "", f"![Fig. 5]({nyquist.name})", "", f"![Fig. 6]({step.name})"]
    for warning in decision.warnings:
        lines += ["", f"> warning: {warning}"]
    summary = out / "report.md"
    summary.write_text("\n".join(lines) + "\n")
    written.append(summary)
    return written
