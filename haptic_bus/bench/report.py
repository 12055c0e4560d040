"""The benchmark's tables (Markdown) and plots (PNG) from the ``bench.json`` dictionary."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ERROR_FLOOR = 1e-17  # plotted for an error of exactly 0


def _t(seconds: float | None) -> str:
    """A duration with a unit that keeps 3 significant digits."""
    if seconds is None:
        return "-"
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6)):
        if abs(seconds) >= scale:
            return f"{seconds / scale:.3g} {unit}"
    return f"{seconds / 1e-9:.3g} ns"


def _e(value: float | None) -> str:
    if value is None:
        return "-"
    return "0" if value == 0 else f"{value:.1e}"


def _r(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _unavailable(section: dict) -> str | None:
    return None if section.get("available", True) else f"not available: {section.get('reason')}"


def markdown(result: dict) -> str:
    """All tables of one benchmark run, with the machine and the command."""
    m = result["machine"]
    v = m["versions"]
    out = [f"# haptic-bus bench{' --quick' if result['quick'] else ''}",
           "",
           f"{m['date']}; {m['platform']}; {m['cpu']} ({m['cpu_count']} CPUs); Python {m['python']}; "
           + ", ".join(f"{k} {val}" for k, val in v.items() if val) + f". Total {result['total_seconds']:.1f} s.",
           "Times are medians of repeats in this run; ratios compare figures measured side by side."]
    if "interrupted" in result:
        out += ["", f"**Interrupted (Ctrl-C) in section {result['interrupted']}: only the sections before it ran.**"]
    sections = result["sections"]

    s = sections.get("passivity")
    out += ["", "## 1. Passivity check: time per check vs error of the boundary", ""]
    if s and s.get("available", True):
        rows = [[r["method"], _t(r["time_per_check_s"]), _r(r["time_ratio_to_exact"]), _e(r["error_K_median"]),
                 _e(r["error_K_max"]), _e(r["error_B_median"]), _e(r["error_B_max"]), str(r["points"])]
                for r in s["methods"]]
        out.append(_table(["method", "time/check", "x exact", "err K med", "err K max", "err B med", "err B max",
                           "points"], rows))
        out += ["", f"Relative error of the largest passive K (at the point's B) and B (at its K) against a "
                    f"40-digit mpmath reference (all references verified: {s['all_references_verified']}). "
                    f"Exact criterion's boundary search: {_t(s['boundary_time_s'].get('exact'))} per boundary. "
                    f"Eq. (24) region map over 10^6 (alpha, beta) points: {_t(s.get('region_map_1e6_s'))}. "
                    f"python-control: {s['control_note']}."]
    else:
        out.append(_unavailable(s or {"available": False, "reason": "not run"}))

    s = sections.get("plant")
    out += ["", "## 2. Plant simulation: time per simulated second vs trajectory error", ""]
    if s and s.get("available", True):
        sc = s["scenario"]
        rows = [[r["method"], _t(r["time_per_simulated_s"]), _r(r["time_ratio_to_exact"]), _e(r["relative_error"])]
                for r in s["methods"]]
        out.append(_table(["method", "time / simulated s", "x exact ZOH", "max rel. error"], rows))
        out += ["", f"m = {sc['m']} kg, b = {sc['b']} N s/m, T = {sc['T']} s (c = {sc['c']:.3g}), delay {sc['delay']}, "
                    f"wall K = {sc['K']} N/m, B = {sc['B']} N s/m at {sc['wall_at'] * 1e3:g} mm; push {sc['push_N']} N, "
                    f"release at {sc['release_s']} s, {sc['duration_s']} s simulated."]
    else:
        out.append(_unavailable(s or {"available": False, "reason": "not run"}))

    s = sections.get("scene")
    out += ["", "## 3. Scene cost: controller compute per cycle", ""]
    if s and s.get("available", True):
        rows = [[str(r["objects"]), _t(r["compiled_cycle_p50_s"]), _r(r["compiled_cycle_ratio_to_one_object"]),
                 _t(r["naive_cycle_p50_s"]), _r(r["naive_over_compiled_cycle"]), _t(r["compiled_force_s"]),
                 _t(r["naive_force_s"])] for r in s["rows"]]
        out.append(_table(["objects", "compiled p50", "x 1 object", "naive p50", "naive/compiled", "force() compiled",
                           "force() naive"], rows))
        tg = s["target"]
        out += ["", f"Issue-4 targets: one wall {_t(tg['one_wall_p50_s'])} median (target <= 5 us: "
                    f"{'met' if tg['one_wall_met'] else 'NOT met'}); 1000 objects / one wall = "
                    f"{tg['thousand_over_one']:.2f} (target <= 1.5: {'met' if tg['thousand_met'] else 'NOT met'})."]
    else:
        out.append(_unavailable(s or {"available": False, "reason": "not run"}))

    s = sections.get("loop")
    out += ["", "## 4. The loop: closed-loop cycles per second (virtual time)", ""]
    if s and s.get("available", True):
        rows = []
        for link in s["links"].values():
            if link["available"]:
                rows.append([link["label"], f"{link['controller_cycles_per_s']:.0f}", _r(link.get("ratio_to_virtual")),
                             f"{link['bare_cycles_per_s']:.0f}", _t(link.get("controller_compute_p50_s"))])
            else:
                rows.append([link["label"], "not available", "-", "-", link["reason"]])
        out.append(_table(["link", "controller cycles/s", "x virtual", "bare read/write cycles/s",
                           "controller compute p50"], rows))
        modbus = s["links"].get("modbus_tcp", {})
        if modbus.get("bench_cycle"):
            out += ["", "haptic_bus.bench.modbus_poll.bench_cycle: " + "; ".join(
                f"{mode} {b['cycles_per_s']:.0f} cycles/s ({b['requests_per_cycle']:.2f} requests/cycle, round trip "
                f"p50 {_t(b['round_trip_p50_s'])})" for mode, b in modbus["bench_cycle"].items()) + "."]
        c = s["pdo_codec"]
        out += ["", f"PDO codec, same {c['frames']} frames: hot path {_t(c['hot_path_s'])}/cycle, canopen generic PDO "
                    f"{_t(c['generic_s'])}/cycle: generic/hot = {c['ratio_generic_over_hot']:.1f}."]
    else:
        out.append(_unavailable(s or {"available": False, "reason": "not run"}))

    s = sections.get("bus")
    out += ["", "## 5. The bus against its physical limit (worst-case stuffing)", ""]
    if s and s.get("available", True):
        mp_, nf = s["mappings"]["minimal"], s["mappings"]["naive_full"]
        out.append(_table(["mapping", "TPDO bytes", "RPDO bytes", "bits/axis/cycle", "1 axis + SYNC"], [
            ["minimal", str(mp_["tpdo_frame_bytes"]), str(mp_["rpdo_frame_bytes"]), str(mp_["bits_per_axis"]),
             str(mp_["bits_one_axis_cycle"])],
            ["naive full", str(nf["tpdo_frame_bytes"]), str(nf["rpdo_frame_bytes"]), str(nf["bits_per_axis"]),
             str(nf["bits_one_axis_cycle"])]]))
        out.append("")
        rows = [[f"{r['bitrate'] // 1000}k", f"{r['minimal']['load_one_axis']:.1%}", str(r["minimal"]["axes_fit"]),
                 _t(r["minimal"]["latency_one_axis_s"]), f"{r['naive_full']['load_one_axis']:.1%}",
                 str(r["naive_full"]["axes_fit"]), _t(r["naive_full"]["latency_one_axis_s"])] for r in s["bitrates"]]
        out.append(_table(["bit/s", "minimal: load 1 axis", "axes fit", "latency", "naive: load 1 axis", "axes fit",
                           "latency"], rows))
        out += ["", f"T = {s['period_s'] * 1e3:g} ms, load ceiling {s['load_ceiling']:.0%}; naive/minimal bits per axis "
                    f"= {s['naive_over_minimal_bits']:.2f}. Minimal: " + ", ".join(mp_["tpdo_objects"] + mp_["rpdo_objects"])
                + ". Naive full: " + ", ".join(nf["tpdo_objects"] + nf["rpdo_objects"]) + "."]
        meas = s["measured_on_virtual_bus"]
        if meas.get("available", True):
            out += ["", "BusLoadMeter on the frames actually exchanged (virtual bus): " + "; ".join(
                f"{k}: {val['meter_bits_median']:.0f} bits/cycle (model {val['model_bits']})" for k, val in meas.items()) + "."]
    else:
        out.append(_unavailable(s or {"available": False, "reason": "not run"}))

    s = sections.get("realtime")
    out += ["", "## 6. Real time", ""]
    if s and s.get("available", True):
        lat, per = s["lateness_s"], s["period_error_abs_s"]
        out.append(_table(["", "p50", "p99", "p99.9", "max"], [
            ["start lateness", _t(lat.get("p50")), _t(lat.get("p99")), _t(lat.get("p99.9")), _t(lat.get("max"))],
            ["period error (abs)", _t(per.get("p50")), _t(per.get("p99")), _t(per.get("p99.9")), _t(per.get("max"))],
            ["bare clock lateness", *(_t(s["bare_clock"]["lateness_s"].get(k)) for k in ("p50", "p99", "p99.9", "max"))]]))
        sch = s["scheduler"]
        out += ["", f"T = {s['period_s'] * 1e3:g} ms for {s['duration_s']:g} s ({s['cycles']} cycles): {s['overruns']} "
                    f"overruns (start later than deadline + T), {s['late_over_100us']} starts > 100 us late; the bare clock "
                    f"(no drive, no controller, same duration): {s['bare_clock']['overruns']} overruns, "
                    f"{s['bare_clock']['late_over_100us']} starts > 100 us late. Clock: "
                    f"{s['clock']}; OS policy {sch.get('policy')}, nice {sch.get('nice')}, CPUs {sch.get('affinity')}, "
                    f"timer slack {sch.get('timer_slack_ns')} ns."]
    else:
        out.append(_unavailable(s or {"available": False, "reason": "not run"}))
    return "\n".join(out) + "\n"


def _loglog(ax, points, label, marker="o", line=False):
    xs = [p[0] for p in points]
    ys = [max(p[1], ERROR_FLOOR) for p in points]
    ax.loglog(xs, ys, marker=marker, linestyle="-" if line else "none", label=label)


def plots(result: dict, out_dir: Path) -> list[Path]:
    """PNG plots of sections 1-3 (and the real-time lateness); returns the paths written."""
    written = []
    sections = result["sections"]
    s = sections.get("passivity")
    if s and s.get("available", True):
        fig, ax = plt.subplots(figsize=(7, 5))
        for r in s["methods"]:
            _loglog(ax, [(r["time_per_check_s"], r["error_max"])], r["method"])
        ax.axhline(ERROR_FLOOR, color="grey", lw=0.5)
        ax.set_xlabel("time per check (s)")
        ax.set_ylabel("largest relative error of the boundary (K and B)")
        ax.set_title("Passivity check: run time vs error")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=8)
        written.append(_save(fig, out_dir / "passivity_time_vs_error.png"))
    s = sections.get("plant")
    if s and s.get("available", True):
        fig, ax = plt.subplots(figsize=(7, 5))
        families: dict[str, list] = {}
        for r in s["methods"]:
            families.setdefault(r["family"], []).append((r["time_per_simulated_s"], r["relative_error"]))
        labels = {"exact": "exact ZOH", "euler": "Euler 1..1000 sub-steps", "rk4": "RK4 1..1000 sub-steps",
                  "ivp_RK45": "solve_ivp RK45 (tolerances)", "ivp_DOP853": "solve_ivp DOP853 (tolerances)"}
        for family, points in families.items():
            _loglog(ax, points, labels.get(family, family), line=len(points) > 1)
        ax.set_xlabel("run time per simulated second (s)")
        ax.set_ylabel("largest relative trajectory error")
        ax.set_title("Plant simulation in the closed loop: run time vs error")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=8)
        written.append(_save(fig, out_dir / "plant_time_vs_error.png"))
    s = sections.get("scene")
    if s and s.get("available", True):
        fig, ax = plt.subplots(figsize=(7, 5))
        n = [r["objects"] for r in s["rows"]]
        ax.loglog(n, [r["compiled_cycle_p50_s"] for r in s["rows"]], "o-", label="compiled scene (bisect)")
        ax.loglog(n, [r["naive_cycle_p50_s"] for r in s["rows"]], "s-", label="per-object loop (no culling)")
        ax.axhline(5e-6, color="grey", ls="--", lw=0.8, label="issue-4 target, one wall (5 us)")
        ax.set_xlabel("scene objects")
        ax.set_ylabel("controller compute per cycle, median (s)")
        ax.set_title("Scene cost")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=8)
        written.append(_save(fig, out_dir / "scene_cost.png"))
    return written


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
